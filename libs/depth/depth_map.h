#pragma once
// Per-view depth as every depth stage produces it: planar depth in metres
// (0 where none), a confidence in [0, 1], and the foreground/background label
// from the volume V (BRIEF §1: a pixel whose depth falls inside V is foreground).
#include <cstddef>
#include <cstdint>
#include <vector>
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

// A depth map held as its set pixels only (those with a depth, confidence or
// label), for the sparse maps a streaming stage keeps waiting: a sparse map of
// depth from gradients sets a few to a few tens of percent of its pixels, and
// a 1280×720 DepthMap is 8.3 MB however few. Unpack gives back the map bit
// for bit (an empty confidence or label stays empty).
class PackedDepthMap {
 public:
  PackedDepthMap() = default;
  static PackedDepthMap Pack(const DepthMap& map);
  DepthMap Unpack() const;
  // Heap bytes held.
  std::size_t Bytes() const;
  int Count() const { return static_cast<int>(index_.size()); }

 private:
  int rows_ = 0, cols_ = 0;
  bool has_confidence_ = false, has_label_ = false;
  std::vector<std::uint32_t> index_;  // row-major pixel index
  std::vector<float> depth_, confidence_;
  std::vector<std::uint8_t> label_;
};

}  // namespace lfrecon
