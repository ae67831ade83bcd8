#pragma once
// Bilinear colour samples for the photometric checks of this library.
#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace lfrecon {

// Bilinear sample of a CV_32FC3 image at COLMAP coordinates (pixel centres at
// +0.5), in single precision (the inner loops); false outside.
inline bool SampleBgr(const cv::Mat& image, float x, float y, Eigen::Vector3f* out) {
  const float fx = x - 0.5f, fy = y - 0.5f;
  if (!(fx >= 0.0f && fy >= 0.0f)) return false;  // also rejects NaN
  const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
  if (x0 + 1 >= image.cols || y0 + 1 >= image.rows) return false;
  const float ax = fx - x0, ay = fy - y0;
  const float* r0 = image.ptr<float>(y0) + 3 * x0;
  const float* r1 = image.ptr<float>(y0 + 1) + 3 * x0;
  const float w00 = (1 - ax) * (1 - ay), w01 = ax * (1 - ay), w10 = (1 - ax) * ay, w11 = ax * ay;
  for (int c = 0; c < 3; ++c) (*out)[c] = w00 * r0[c] + w01 * r0[3 + c] + w10 * r1[c] + w11 * r1[3 + c];
  return true;
}

}  // namespace lfrecon
