#pragma once
// Bilinear sampling in COLMAP pixel coordinates (upper-left pixel centre at
// (0.5, 0.5)). Kept inline: these run in the innermost loops (a few thousand
// samples per pixel of depth from gradients).
#include <Eigen/Core>
#include <cmath>
#include <opencv2/core.hpp>

namespace lfrecon {

// A CV_32F image (1 or 3 channels) for the innermost loops: the pointer,
// row stride and sampling bounds, read once instead of from cv::Mat per sample.
struct FloatImage {
  const float* data = nullptr;
  std::ptrdiff_t stride = 0;  // floats per row
  double max_x = -1, max_y = -1;  // a sample at f = x - 0.5 needs 0 <= f < max

  FloatImage() = default;
  explicit FloatImage(const cv::Mat& image)
      : data(image.ptr<float>()),
        stride(static_cast<std::ptrdiff_t>(image.step1())),
        max_x(image.cols - 1),
        max_y(image.rows - 1) {}

  // The 2×2 cell of a sample at (x, y): false (and nothing sampled) unless it
  // lies inside the image. Truncation is floor here (f >= 0), and cheaper: on
  // x86-64 without SSE4.1, floor() is a long instruction sequence.
  bool Cell(double x, double y, const float** r0, float* ax, float* ay, int channels) const {
    const double fx = x - 0.5, fy = y - 0.5;
    if (!(fx >= 0.0) || !(fx < max_x) || !(fy >= 0.0) || !(fy < max_y)) return false;
    const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
    *ax = static_cast<float>(fx - x0);
    *ay = static_cast<float>(fy - y0);
    *r0 = data + y0 * stride + channels * x0;
    return true;
  }
  bool Inside(double x, double y) const {
    const double fx = x - 0.5, fy = y - 0.5;
    return fx >= 0.0 && fx < max_x && fy >= 0.0 && fy < max_y;
  }
  bool Sample1(double x, double y, float* out) const {
    const float* r0;
    float ax, ay;
    if (!Cell(x, y, &r0, &ax, &ay, 1)) return false;
    const float* r1 = r0 + stride;
    const float top = r0[0] + ax * (r0[1] - r0[0]), bottom = r1[0] + ax * (r1[1] - r1[0]);
    *out = top + ay * (bottom - top);
    return true;
  }
  bool Sample3(double x, double y, Eigen::Vector3f* out) const {
    const float* r0;
    float ax, ay;
    if (!Cell(x, y, &r0, &ax, &ay, 3)) return false;
    const float* r1 = r0 + stride;
    for (int c = 0; c < 3; ++c) {
      const float top = r0[c] + ax * (r0[3 + c] - r0[c]), bottom = r1[c] + ax * (r1[3 + c] - r1[c]);
      (*out)[c] = top + ay * (bottom - top);
    }
    return true;
  }
};

}  // namespace lfrecon
