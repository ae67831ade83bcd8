#pragma once
// Bilinear sampling in COLMAP pixel coordinates (upper-left pixel centre at
// (0.5, 0.5)). Kept inline: these run in the innermost loops.
#include <Eigen/Core>
#include <cmath>
#include <opencv2/core.hpp>

namespace lfrecon {

// Samples a CV_32FC3 image at COLMAP coordinates (x, y). Returns false (and
// leaves *out alone) if the 2x2 neighbourhood is not inside the image.
inline bool SampleBilinear3(const cv::Mat& image, double x, double y, Eigen::Vector3f* out) {
  const double fx = x - 0.5, fy = y - 0.5;
  const int x0 = static_cast<int>(std::floor(fx)), y0 = static_cast<int>(std::floor(fy));
  if (x0 < 0 || y0 < 0 || x0 + 1 >= image.cols || y0 + 1 >= image.rows) return false;
  const float ax = static_cast<float>(fx - x0), ay = static_cast<float>(fy - y0);
  const float* r0 = image.ptr<float>(y0) + 3 * x0;
  const float* r1 = image.ptr<float>(y0 + 1) + 3 * x0;
  const float w00 = (1 - ax) * (1 - ay), w01 = ax * (1 - ay), w10 = (1 - ax) * ay, w11 = ax * ay;
  for (int c = 0; c < 3; ++c) (*out)[c] = w00 * r0[c] + w01 * r0[3 + c] + w10 * r1[c] + w11 * r1[3 + c];
  return true;
}

// Samples a single-channel CV_32F image; returns false outside.
inline bool SampleBilinear1(const cv::Mat& image, double x, double y, float* out) {
  const double fx = x - 0.5, fy = y - 0.5;
  const int x0 = static_cast<int>(std::floor(fx)), y0 = static_cast<int>(std::floor(fy));
  if (x0 < 0 || y0 < 0 || x0 + 1 >= image.cols || y0 + 1 >= image.rows) return false;
  const float ax = static_cast<float>(fx - x0), ay = static_cast<float>(fy - y0);
  const float* r0 = image.ptr<float>(y0) + x0;
  const float* r1 = image.ptr<float>(y0 + 1) + x0;
  *out = (1 - ax) * (1 - ay) * r0[0] + ax * (1 - ay) * r0[1] + (1 - ax) * ay * r1[0] + ax * ay * r1[1];
  return true;
}

}  // namespace lfrecon
