#pragma once
// Per-view depth as every depth stage produces it: planar depth in metres
// (0 where none), a confidence in [0, 1], and the foreground/background label
// from the volume V (BRIEF §1: a pixel whose depth falls inside V is foreground).
#include <cstdint>
#include <opencv2/core.hpp>

namespace lfrecon {

enum class DepthLabel : std::uint8_t { kNone = 0, kForeground = 1, kBackground = 2 };

struct DepthMap {
  cv::Mat depth;       // CV_32F
  cv::Mat confidence;  // CV_32F
  cv::Mat label;       // CV_8U, DepthLabel values

  DepthMap() = default;
  DepthMap(int rows, int cols)
      : depth(cv::Mat::zeros(rows, cols, CV_32F)),
        confidence(cv::Mat::zeros(rows, cols, CV_32F)),
        label(cv::Mat::zeros(rows, cols, CV_8U)) {}

  int CountValid() const { return depth.empty() ? 0 : cv::countNonZero(depth > 0); }
};

}  // namespace lfrecon
