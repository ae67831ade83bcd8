// Free space added before fusion: the gated background floor and the mask's free space.
#include "fusion/free_space.h"

#include <gtest/gtest.h>

#include <opencv2/core.hpp>

namespace lfrecon {
namespace {

TEST(GatedBackgroundFloor, RaisesOnlyBackgroundFarFromTheForeground) {
  // One row: foreground at columns 0-1, background (confidence 0.01) at 2-18, none at 19.
  DepthMap m(1, 20);
  for (int c = 0; c < 19; ++c) {
    m.depth.at<float>(0, c) = c < 2 ? 1.0f : 3.0f;
    m.confidence.at<float>(0, c) = 0.01f;
    m.label.at<std::uint8_t>(0, c) = static_cast<std::uint8_t>(c < 2 ? DepthLabel::kForeground : DepthLabel::kBackground);
  }
  m.confidence.at<float>(0, 12) = 0.2f;  // already above the floor
  // Identity view (K = I): pixel column c at depth d is the point (d (c + ½), d / 2, d);
  // V holds depth 1 (foreground), not depth 3 (background beyond V).
  const BoundingBox V{Eigen::Vector3d(-100, -1, 0), Eigen::Vector3d(100, 1, 2)};
  const DepthMap out = WithGatedBackgroundFloor(m, PinholeView(), V, 0.05, 6.0);
  for (int c = 0; c < 20; ++c) {
    const float conf = out.confidence.at<float>(0, c);
    if (c < 2) EXPECT_FLOAT_EQ(conf, 0.01f) << "foreground is not changed: " << c;
    else if (c < 7) EXPECT_FLOAT_EQ(conf, 0.01f) << "background within 6 px of the foreground keeps its own: " << c;
    else if (c == 12) EXPECT_FLOAT_EQ(conf, 0.2f);
    else if (c < 19) EXPECT_FLOAT_EQ(conf, 0.05f) << "background beyond the gate is raised: " << c;
    else EXPECT_FLOAT_EQ(conf, 0.0f) << "no depth stays none";
  }
  EXPECT_FLOAT_EQ(m.confidence.at<float>(0, 9), 0.01f) << "the input is not changed";
  EXPECT_FLOAT_EQ(WithGatedBackgroundFloor(m, PinholeView(), V, 0.0, 6.0).confidence.at<float>(0, 9), 0.01f);
  // Gate 0: every background depth beyond V.
  EXPECT_FLOAT_EQ(WithGatedBackgroundFloor(m, PinholeView(), V, 0.05, 0.0).confidence.at<float>(0, 2), 0.05f);
  // A background-labelled depth inside V (a thin part the propagation called
  // background) is not raised, and gates its neighbours like foreground.
  DepthMap t = m;
  t.depth = m.depth.clone();
  t.depth.at<float>(0, 15) = 1.0f;
  const DepthMap tout = WithGatedBackgroundFloor(t, PinholeView(), V, 0.05, 6.0);
  EXPECT_FLOAT_EQ(tout.confidence.at<float>(0, 15), 0.01f);
  EXPECT_FLOAT_EQ(tout.confidence.at<float>(0, 10), 0.01f) << "5 px from the depth inside V";
  EXPECT_FLOAT_EQ(tout.confidence.at<float>(0, 8), 0.05f) << "6 px from both";
  // `protect` pixels gate like foreground (the sparse depths inside V that the
  // pipeline passes), whatever the dense map says there.
  cv::Mat protect = cv::Mat::zeros(1, 20, CV_8U);
  protect.at<std::uint8_t>(0, 16) = 255;
  const DepthMap pout = WithGatedBackgroundFloor(m, PinholeView(), V, 0.05, 6.0, protect);
  EXPECT_FLOAT_EQ(pout.confidence.at<float>(0, 9), 0.05f) << "7 px from the foreground and from the protected pixel";
  EXPECT_FLOAT_EQ(pout.confidence.at<float>(0, 11), 0.01f) << "5 px from the protected pixel";
  EXPECT_FLOAT_EQ(pout.confidence.at<float>(0, 16), 0.01f) << "the protected pixel itself";
  EXPECT_FLOAT_EQ(pout.confidence.at<float>(0, 18), 0.01f);
}

TEST(MaskFreeSpace, PixelsOutsideTheMaskBeyondTheMarginSeeEmptySpace) {
  // One row: a halo of foreground depth over columns 0-9, the object's mask
  // at columns 4-5, background (confidence 0.01) at 10-15, nothing at 16-19.
  DepthMap m(1, 20);
  constexpr auto kFg = static_cast<std::uint8_t>(DepthLabel::kForeground);
  constexpr auto kBg = static_cast<std::uint8_t>(DepthLabel::kBackground);
  for (int c = 0; c < 16; ++c) {
    m.depth.at<float>(0, c) = c < 10 ? 1.0f : 3.0f;
    m.confidence.at<float>(0, c) = c < 10 ? 0.3f : 0.01f;
    m.label.at<std::uint8_t>(0, c) = c < 10 ? kFg : kBg;
  }
  m.confidence.at<float>(0, 12) = 0.5f;  // a confident background keeps its confidence
  cv::Mat mask = cv::Mat::zeros(1, 20, CV_8U);
  mask.at<std::uint8_t>(0, 4) = mask.at<std::uint8_t>(0, 5) = 255;
  const DepthMap out = WithMaskFreeSpace(m, mask, 0.1, 2.0);
  for (int c = 0; c < 20; ++c) {
    const bool near = c >= 2 && c <= 7;  // within 2 px of the mask
    if (near) {
      EXPECT_FLOAT_EQ(out.depth.at<float>(0, c), 1.0f) << c;
      EXPECT_FLOAT_EQ(out.confidence.at<float>(0, c), 0.3f) << c;
      EXPECT_EQ(out.label.at<std::uint8_t>(0, c), kFg) << c;
      continue;
    }
    EXPECT_FLOAT_EQ(out.depth.at<float>(0, c), 0.0f) << "the whole ray through V is free: " << c;
    EXPECT_EQ(out.label.at<std::uint8_t>(0, c), kBg) << c;
    EXPECT_FLOAT_EQ(out.confidence.at<float>(0, c), c == 12 ? 0.5f : 0.1f) << c;
  }
  EXPECT_FLOAT_EQ(m.depth.at<float>(0, 0), 1.0f) << "the input is not changed";
  // No mask, a mask of another size, or confidence 0: the map as it was.
  for (const DepthMap& same : {WithMaskFreeSpace(m, cv::Mat(), 0.1, 2.0),
                               WithMaskFreeSpace(m, cv::Mat::zeros(2, 20, CV_8U), 0.1, 2.0),
                               WithMaskFreeSpace(m, mask, 0.0, 2.0)}) {
    EXPECT_FLOAT_EQ(same.depth.at<float>(0, 0), 1.0f);
    EXPECT_EQ(same.label.at<std::uint8_t>(0, 0), kFg);
  }
  // An empty mask: no object in the view, every pixel free.
  const DepthMap none = WithMaskFreeSpace(m, cv::Mat::zeros(1, 20, CV_8U), 0.1, 2.0);
  EXPECT_EQ(cv::countNonZero(none.depth), 0);
}

}  // namespace
}  // namespace lfrecon
