#pragma once
// The squared colour difference that C^c (eq. 4) and ρ (eq. 9) put under
// their Gaussians, with the chroma part optionally down-weighted (ours).
//
// Why: JPEG and video codecs store chroma (Cb, Cr) at half resolution (4:2:0)
// and only luma Y at full resolution, so near an edge or on a part a few
// pixels wide the decoded chroma is a blend with the background that differs
// from view to view with the part's position on the 2×2 chroma grid. Those
// errors leave Y unchanged: in BGR they lie along directions e with
// Y(e) = 0.114 e_B + 0.587 e_G + 0.299 e_R = 0 (Rec. 601, the weights of
// cv::COLOR_BGR2GRAY and of JPEG's YCbCr). A difference d is split into its
// luma part Y(d)·(1, 1, 1) and the rest e = d − Y(d)·(1, 1, 1), and
//   D² = 3·Y(d)² + w·‖e‖²,
// so w = 1 compares luma as ‖d‖² does for a grey difference and w < 1 trusts
// chroma less. chroma_weight == 1 returns ‖d‖² itself: the paper's test,
// bit for bit.
#include <Eigen/Core>

namespace lfrecon {

inline float ColourDifference2(const Eigen::Vector3f& bgr_a, const Eigen::Vector3f& bgr_b, float chroma_weight) {
  const Eigen::Vector3f d = bgr_a - bgr_b;
  if (chroma_weight == 1.0f) return d.squaredNorm();
  const float y = 0.114f * d[0] + 0.587f * d[1] + 0.299f * d[2];
  const Eigen::Vector3f e = d - Eigen::Vector3f::Constant(y);
  return 3.0f * y * y + chroma_weight * e.squaredNorm();
}

}  // namespace lfrecon
