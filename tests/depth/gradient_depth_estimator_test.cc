#include "depth/gradient_depth_estimator.h"

#include <gtest/gtest.h>

#include "synth_views.h"
#include "util/error.h"

namespace lfrecon {
namespace {

using testing::MakeSynthViews;
using testing::ScoreDepth;

TEST(GradientDepthEstimator, TexturedPlaneWithinHalfPercent) {
  // The plane scene's rig is a 60° arc facing the plane; its middle view sees
  // the plane fronto-parallel.
  const auto v = MakeSynthViews("plane", 60, 5.0, 320, 180, 120);
  ASSERT_GE(v.neighbors.size(), 8u);
  const DepthMap m = GradientDepthEstimator(GradientDepthOptions()).Estimate(v.ref, v.NeighborPtrs(), v.volume);
  const auto s = ScoreDepth(v, m, /*skip_edges=*/true);
  std::printf("plane: accuracy %.4f coverage %.4f over %lld edge pixels\n", s.Accuracy(), s.Coverage(), s.expected);
  ASSERT_GT(s.expected, 1000);
  EXPECT_GE(s.Accuracy(), 0.95);
  EXPECT_GE(s.Coverage(), 0.95);
}

TEST(GradientDepthEstimator, TexturedSphereWithinHalfPercent) {
  const auto v = MakeSynthViews("sphere");
  const DepthMap m = GradientDepthEstimator(GradientDepthOptions()).Estimate(v.ref, v.NeighborPtrs(), v.volume);
  const auto s = ScoreDepth(v, m, /*skip_edges=*/true);
  std::printf("sphere: accuracy %.4f coverage %.4f over %lld edge pixels\n", s.Accuracy(), s.Coverage(), s.expected);
  ASSERT_GT(s.expected, 1000);
  EXPECT_GE(s.Accuracy(), 0.95);
  EXPECT_GE(s.Coverage(), 0.95);
  // Labels: estimates on the sphere are foreground.
  long long fg = 0, total = 0;
  for (int r = 0; r < m.depth.rows; ++r)
    for (int c = 0; c < m.depth.cols; ++c)
      if (v.foreground.at<std::uint8_t>(r, c) && !v.near_edge.at<std::uint8_t>(r, c) && m.depth.at<float>(r, c) > 0) {
        ++total;
        fg += m.label.at<std::uint8_t>(r, c) == static_cast<std::uint8_t>(DepthLabel::kForeground);
      }
  EXPECT_GE(static_cast<double>(fg) / total, 0.97);
}

TEST(GradientDepthEstimator, HierarchyBeatsNearestNeighboursOnly) {
  const auto v = MakeSynthViews("sphere");
  GradientDepthOptions nearest;
  nearest.use_hierarchy = false;
  const auto all = ScoreDepth(v, GradientDepthEstimator(GradientDepthOptions()).Estimate(v.ref, v.NeighborPtrs(), v.volume), true);
  const auto near = ScoreDepth(v, GradientDepthEstimator(nearest).Estimate(v.ref, v.NeighborPtrs(), v.volume), true);
  std::printf("all views within 5°: %.4f, nearest only: %.4f\n", all.Accuracy(), near.Accuracy());
  EXPECT_GT(all.Accuracy(), near.Accuracy() + 0.1);
}

TEST(GradientDepthEstimator, TexturelessThinCylinderGetsForegroundDepthOnItsSilhouette) {
  const auto v = MakeSynthViews("thin_cylinder");
  const DepthMap m = GradientDepthEstimator(GradientDepthOptions()).Estimate(v.ref, v.NeighborPtrs(), v.volume);
  // Pixels where the reference sees the cylinder (or whose samples touch it).
  const cv::Mat thin = synth::ThinMask(v.sequence->scene(), v.truth.labels);
  ASSERT_GT(cv::countNonZero(thin), 20);
  cv::Mat band;
  cv::dilate(thin, band, cv::Mat::ones(3, 3, CV_8U));
  long long band_px = 0, with_fg_depth = 0, accurate = 0;
  for (int r = 0; r < band.rows; ++r)
    for (int c = 0; c < band.cols; ++c) {
      if (!band.at<std::uint8_t>(r, c)) continue;
      ++band_px;
      if (m.label.at<std::uint8_t>(r, c) != static_cast<std::uint8_t>(DepthLabel::kForeground)) continue;
      ++with_fg_depth;
      // Compare with the cylinder's depth at the nearest pixel that sees it.
      double t = 0;
      for (int dc = 0; dc <= 2 && t == 0; ++dc)
        for (int sgn : {-1, 1}) {
          const int cc = std::clamp(c + sgn * dc, 0, band.cols - 1);
          if (thin.at<std::uint8_t>(r, cc)) {
            t = v.truth.depth.at<double>(r, cc);
            break;
          }
        }
      if (t > 0 && std::abs(m.depth.at<float>(r, c) - t) <= 0.01 * t) ++accurate;
    }
  std::printf("thin cylinder band: %lld px, %lld with foreground depth, %lld within 1%%\n", band_px, with_fg_depth,
              accurate);
  EXPECT_GE(static_cast<double>(with_fg_depth) / band_px, 0.5);
  EXPECT_GE(static_cast<double>(accurate) / std::max(1LL, with_fg_depth), 0.65);
}

TEST(GradientDepthEstimator, DegenerateInputGivesEmptyMapsNotNaN) {
  const auto v = MakeSynthViews("sphere", 0, 5.0, 96, 54, 480);
  const GradientDepthEstimator est{GradientDepthOptions()};
  // No neighbour at all.
  DepthMap m = est.Estimate(v.ref, {}, v.volume);
  EXPECT_EQ(m.CountValid(), 0);
  EXPECT_EQ(m.depth.size(), v.ref.image.size());
  // Neighbours beyond 5°: a view of the same sequence 90° away.
  ViewImage far{v.sequence->View(120), v.sequence->RenderImage(120), cv::Mat(), cv::Mat()};
  m = est.Estimate(v.ref, {&far}, v.volume);
  EXPECT_EQ(m.CountValid(), 0);
  // A blank frame (no gradient anywhere).
  ViewImage blank = v.ref;
  blank.image = cv::Mat(v.ref.image.size(), CV_32FC3, cv::Scalar(0.5, 0.5, 0.5));
  m = est.Estimate(blank, v.NeighborPtrs(), v.volume);
  EXPECT_EQ(m.CountValid(), 0);
  // Coincident cameras: the same pose and image as the reference.
  ViewImage same = v.ref;
  m = est.Estimate(v.ref, {&same, &same}, v.volume);
  EXPECT_EQ(m.CountValid(), 0);
  // Any output is finite.
  m = est.Estimate(v.ref, v.NeighborPtrs(), v.volume);
  EXPECT_GT(m.CountValid(), 0);
  EXPECT_TRUE(cv::checkRange(m.depth) && cv::checkRange(m.confidence));
}

TEST(GradientDepthEstimatorOptions, CheckRejectsBadValues) {
  GradientDepthOptions o;
  o.patch_length = 4;
  EXPECT_THROW(o.Check(), OptionError);
  o = GradientDepthOptions();
  o.sigma_c = 0;
  EXPECT_THROW(GradientDepthEstimator{o}, OptionError);
}

}  // namespace
}  // namespace lfrecon
