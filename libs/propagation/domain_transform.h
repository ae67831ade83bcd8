#pragma once
// Edge-aware filtering with the domain transform of Gastal & Oliveira (2011),
// recursive-filter (RF) variant, on images with any number of float channels
// at once. OpenCV's ximgproc::DTFilter implements the same filter but takes at
// most 4 channels per call; the first-order propagation filters 11 channels,
// and one pass over all of them costs about what one 4-channel OpenCV call
// does. tests/propagation/domain_transform_test.cc checks it against OpenCV's
// DTF_RF on the same guide.
//
// Distances along a row (or column) are 1 + (σ_s/σ_r)·Σ_c |ΔI_c| between
// neighbouring pixels of the guide I; iteration i of N uses the feedback
// coefficient a_i = exp(−√2 / σ_H,i), σ_H,i = σ_s·√3·2^(N−i) / √(4^N − 1), and
// runs left→right, right→left, top→bottom, bottom→top.
#include <opencv2/core.hpp>

namespace lfrecon {

class DomainTransformFilter {
 public:
  // `guide`: CV_32FC1 or CV_32FC3; σ_s in pixels, σ_r in guide units.
  DomainTransformFilter(const cv::Mat& guide, double sigma_spatial, double sigma_color, int iterations = 3);

  // Filters `data` (CV_32FC(n), n >= 1, the guide's size) in place.
  void Apply(cv::Mat& data) const;

 private:
  cv::Mat w_hor_;   // CV_32F, a_1^d between (r, c−1) and (r, c); column 0 unused
  cv::Mat w_vert_;  // CV_32F, a_1^d between (r−1, c) and (r, c); row 0 unused
  int iterations_ = 3;
};

}  // namespace lfrecon
