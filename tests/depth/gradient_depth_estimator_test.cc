#include "depth/gradient_depth_estimator.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <opencv2/imgproc.hpp>

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

TEST(GradientDepthEstimator, EdgePixelsWhoseRayMissesTheGrownVolumeGetNoDepthAndTheRestAreUnchanged) {
  // A small V in the middle of the textured plane: most of the frame looks
  // beside it. Pixels whose ray meets V grown by ray_margin of its size keep
  // exactly the depth they get without the cut; the others get none.
  auto v = MakeSynthViews("plane", 60, 5.0, 320, 180, 120);
  const Eigen::Vector3d centre = v.volume.Center(), half = 0.05 * v.volume.Extent();
  v.volume.min = centre - half;
  v.volume.max = centre + half;
  GradientDepthOptions every;
  every.ray_margin = -1;
  const GradientDepthOptions cut;  // default margin
  const DepthMap all = GradientDepthEstimator(every).Estimate(v.ref, v.NeighborPtrs(), v.volume);
  const DepthMap some = GradientDepthEstimator(cut).Estimate(v.ref, v.NeighborPtrs(), v.volume);
  const BoundingBox grown = v.volume.Grown(cut.ray_margin * v.volume.Extent().maxCoeff());
  const Eigen::Vector3d eye = v.ref.view.Center();
  long long inside = 0, outside = 0, outside_with_depth = 0, mismatched = 0, leaked = 0;
  for (int r = 0; r < all.depth.rows; ++r)
    for (int c = 0; c < all.depth.cols; ++c) {
      const Eigen::Vector3d dir = v.ref.view.Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), 1.0) - eye;
      const float a = all.depth.at<float>(r, c), b = some.depth.at<float>(r, c);
      if (RayMeetsBox(eye, dir, grown)) {
        inside += a > 0;
        mismatched += a != b || all.confidence.at<float>(r, c) != some.confidence.at<float>(r, c);
      } else {
        ++outside;
        outside_with_depth += a > 0;
        leaked += b > 0;
      }
    }
  std::printf("rays meeting grown V: %lld depths; missing it: %lld pixels, %lld with a depth uncut\n", inside, outside,
              outside_with_depth);
  ASSERT_GT(inside, 100);
  ASSERT_GT(outside_with_depth, 1000);
  EXPECT_EQ(mismatched, 0);
  EXPECT_EQ(leaked, 0);
}

TEST(GradientPeaks, KeepsTheFlanksOfALineAndAtZeroEverything) {
  // A bright vertical line one pixel wide at column 20, blurred (σ 1 px): ‖∇I‖
  // peaks on its two flanks (columns 19 and 21) and vanishes on the line.
  cv::Mat img = cv::Mat::zeros(40, 48, CV_32FC3);
  img.col(20).setTo(cv::Scalar(1, 1, 1));
  cv::GaussianBlur(img, img, cv::Size(0, 0), 1.0);
  const cv::Mat mag = GradientMagnitude(img);
  const cv::Mat peaks = GradientPeaks(img, 1.0);
  for (int r = 5; r < 35; ++r)
    for (int c = 0; c < img.cols; ++c) {
      const bool flank = c == 19 || c == 21;
      EXPECT_EQ(peaks.at<float>(r, c) > 0, flank) << r << " " << c;
      if (flank) EXPECT_EQ(peaks.at<float>(r, c), mag.at<float>(r, c));
    }
  // Half of the neighbour's: the pixels beside the flanks that still have half the slope.
  const cv::Mat half = GradientPeaks(img, 0.5);
  EXPECT_GT(cv::countNonZero(half), cv::countNonZero(peaks));
  const cv::Mat all = GradientPeaks(img, 0.0);
  EXPECT_EQ(cv::countNonZero(all != mag), 0);
}

TEST(GradientDepthEstimator, PeakFractionKeepsTheDepthsOfThePeaksBitForBit) {
  // gradient_peak_fraction only chooses which edge pixels get a depth: those
  // it keeps get exactly the depth and confidence of the full estimate.
  const auto v = MakeSynthViews("plane", 60, 5.0, 320, 180, 120);
  GradientDepthOptions every;
  every.gradient_peak_fraction = 0;
  GradientDepthOptions peaks;
  peaks.gradient_peak_fraction = 1;
  const DepthMap all = GradientDepthEstimator(every).Estimate(v.ref, v.NeighborPtrs(), v.volume);
  const DepthMap some = GradientDepthEstimator(peaks).Estimate(v.ref, v.NeighborPtrs(), v.volume);
  const cv::Mat kept = GradientPeaks(v.ref.image, 1.0);
  long long with_all = 0, with_some = 0, mismatched = 0, leaked = 0;
  for (int r = 0; r < all.depth.rows; ++r)
    for (int c = 0; c < all.depth.cols; ++c) {
      const float a = all.depth.at<float>(r, c), b = some.depth.at<float>(r, c);
      with_all += a > 0;
      with_some += b > 0;
      if (kept.at<float>(r, c) > every.gradient_threshold)
        mismatched += a != b || all.confidence.at<float>(r, c) != some.confidence.at<float>(r, c);
      else
        leaked += b > 0;
    }
  std::printf("depths: every edge pixel %lld, peaks only %lld\n", with_all, with_some);
  EXPECT_EQ(mismatched, 0);
  EXPECT_EQ(leaked, 0);
  EXPECT_LT(with_some, 0.7 * with_all);
  EXPECT_GT(with_some, 0.2 * with_all);
  const auto s = ScoreDepth(v, some, /*skip_edges=*/true);
  EXPECT_GE(s.Accuracy(), 0.95);
}

// Pixels with a depth in a or b: *valid counts them and *label_changed those
// whose validity or label differs; `same(r, c, depth_a, depth_b, label)` is
// called for the others.
template <class Same>
void CompareDepthMaps(const DepthMap& a, const DepthMap& b, long long* valid, long long* label_changed, Same same) {
  *valid = *label_changed = 0;
  for (int r = 0; r < a.depth.rows; ++r)
    for (int c = 0; c < a.depth.cols; ++c) {
      const float da = a.depth.at<float>(r, c), db = b.depth.at<float>(r, c);
      if (!(da > 0) && !(db > 0)) continue;
      ++*valid;
      const std::uint8_t la = a.label.at<std::uint8_t>(r, c);
      if ((da > 0) != (db > 0) || la != b.label.at<std::uint8_t>(r, c)) {
        ++*label_changed;
        continue;
      }
      same(r, c, da, db, la);
    }
}

TEST(GradientDepthEstimator, SettlingOutsideVKeepsLabelsAndForegroundDepths) {
  // The tabletop: objects in V on a textured floor that reaches far outside
  // it. Stopping the levels of a pixel once its depth is settled outside V
  // changes only background depths (coarser: fewer views), never a label
  // beyond a handful of pixels, and leaves foreground depths as they were.
  const auto v = MakeSynthViews("tabletop");
  GradientDepthOptions every;
  every.settle_outside_volume = false;
  GradientDepthOptions settle;
  settle.settle_outside_volume = true;
  const DepthMap all = GradientDepthEstimator(every).Estimate(v.ref, v.NeighborPtrs(), v.volume);
  const DepthMap some = GradientDepthEstimator(settle).Estimate(v.ref, v.NeighborPtrs(), v.volume);
  const auto fg = static_cast<std::uint8_t>(DepthLabel::kForeground);
  long long valid = 0, label_changed = 0, foreground = 0, foreground_changed = 0, background = 0,
            background_changed = 0;
  CompareDepthMaps(all, some, &valid, &label_changed, [&](int r, int c, float a, float b, std::uint8_t label) {
    const bool changed = a != b || all.confidence.at<float>(r, c) != some.confidence.at<float>(r, c);
    if (label == fg) {
      ++foreground;
      foreground_changed += changed;
    } else {
      ++background;
      background_changed += changed;
    }
  });
  std::printf("depths %lld: label or validity changed %lld; foreground %lld (%lld changed), background %lld (%lld "
              "changed)\n",
              valid, label_changed, foreground, foreground_changed, background, background_changed);
  ASSERT_GT(foreground, 1000);
  ASSERT_GT(background, 1000);
  EXPECT_LE(label_changed, 0.001 * valid);
  EXPECT_LE(foreground_changed, 0.001 * foreground);
  // It does stop early: most background pixels end with fewer views.
  EXPECT_GE(background_changed, 0.5 * background);
  // Foreground accuracy against the truth is that of every level.
  const auto sa = ScoreDepth(v, all, /*skip_edges=*/true), ss = ScoreDepth(v, some, /*skip_edges=*/true);
  EXPECT_NEAR(ss.Accuracy(), sa.Accuracy(), 0.002);
  EXPECT_NEAR(ss.Coverage(), sa.Coverage(), 0.002);
}

TEST(GradientDepthEstimator, ReusingTheReferencePatchKeepsDepths) {
  // A later level's patches all centre on the pixel; sampling their reference
  // side once at the predicted depth instead of at each reference point's
  // changes the depths by a small fraction of their error, not the labels.
  const auto v = MakeSynthViews("tabletop");
  GradientDepthOptions resample;
  resample.reuse_reference_patch = false;
  GradientDepthOptions reuse;
  reuse.reuse_reference_patch = true;
  const DepthMap a_map = GradientDepthEstimator(resample).Estimate(v.ref, v.NeighborPtrs(), v.volume);
  const DepthMap b_map = GradientDepthEstimator(reuse).Estimate(v.ref, v.NeighborPtrs(), v.volume);
  long long valid = 0, label_changed = 0, both = 0, moved = 0;
  std::vector<double> rel;
  CompareDepthMaps(a_map, b_map, &valid, &label_changed, [&](int, int, float a, float b, std::uint8_t) {
    ++both;
    moved += a != b;
    rel.push_back(std::abs(b - a) / a);
  });
  ASSERT_GT(both, 10000);
  std::sort(rel.begin(), rel.end());
  const double median = rel[rel.size() / 2], p99 = rel[rel.size() * 99 / 100];
  std::printf("depths %lld: label or validity changed %lld; of %lld, %lld moved, relative change median %.2e, "
              "99th percentile %.2e\n",
              valid, label_changed, both, moved, median, p99);
  EXPECT_LE(label_changed, 0.001 * valid);
  EXPECT_GT(moved, 0.5 * both);  // it does take the other path
  EXPECT_LT(median, 1e-5);
  EXPECT_LT(p99, 1e-3);
  const auto sa = ScoreDepth(v, a_map, /*skip_edges=*/true), sb = ScoreDepth(v, b_map, /*skip_edges=*/true);
  EXPECT_NEAR(sb.Accuracy(), sa.Accuracy(), 0.002);
  EXPECT_NEAR(sb.Coverage(), sa.Coverage(), 0.002);
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

std::vector<PinholeView> SequenceViews(const synth::SynthSequence& seq) {
  std::vector<PinholeView> views;
  for (int i = 0; i < seq.NumFrames(); ++i) views.push_back(seq.View(i));
  return views;
}

TEST(GradientDepthEstimator, HierarchyGridLeavesSpacingsAtOrAboveTheStepUnchanged) {
  // 480 frames per loop, 0.75° apart (the figurines' spacing): every view
  // within 5° is on the grid and used, as with the thinning off.
  synth::SynthOptions so;
  so.scene = "sphere";
  so.frames = 480;
  so.width = 96;
  so.height = 54;
  const auto seq = synth::SynthSequence::Create(so);
  const std::vector<PinholeView> views = SequenceViews(seq);
  const GradientDepthOptions o;
  const std::vector<char> grid = HierarchyGrid(views, o);
  EXPECT_EQ(std::count(grid.begin(), grid.end(), 1), 480);
  std::vector<Eigen::Vector3d> dirs;
  for (const auto& v : views) dirs.push_back(v.ViewingDirection());
  const ViewGraph graph(dirs, o.max_view_angle_deg);
  for (int ref : {0, 100, 479}) {
    std::vector<const PinholeView*> nbs;
    for (int j : graph.Neighbors(ref)) nbs.push_back(&views[j]);
    ASSERT_GE(nbs.size(), 10u);
    EXPECT_EQ(SelectHierarchyViews(views[ref], nbs, {}, o).size(), nbs.size()) << "reference " << ref;
  }
  // The plane rig: 120 frames over 60°, exactly the step (0.5°) apart.
  synth::SynthOptions po;
  po.scene = "plane";
  po.frames = 120;
  po.width = 96;
  po.height = 54;
  const std::vector<PinholeView> plane = SequenceViews(synth::SynthSequence::Create(po));
  const std::vector<char> plane_grid = HierarchyGrid(plane, o);
  EXPECT_EQ(std::count(plane_grid.begin(), plane_grid.end(), 1), 120);
  std::vector<Eigen::Vector3d> plane_dirs;
  for (const auto& v : plane) plane_dirs.push_back(v.ViewingDirection());
  const ViewGraph plane_graph(plane_dirs, o.max_view_angle_deg);
  std::vector<const PinholeView*> nbs;
  for (int j : plane_graph.Neighbors(60)) nbs.push_back(&plane[j]);
  ASSERT_GE(nbs.size(), 16u);
  EXPECT_EQ(SelectHierarchyViews(plane[60], nbs, plane_grid, o).size(), nbs.size());
}

TEST(GradientDepthEstimator, DenseSequenceThinnedToGridKeepsAccuracyWithFewViews) {
  // 3000 frames per loop (0.12° apart, a real video's spacing): ~100 views
  // within 5°. On the grid the hierarchy uses a fraction of them, reaching as
  // far, with the same accuracy.
  const auto v = MakeSynthViews("sphere", 0, 5.0, 320, 180, 3000);
  ASSERT_GE(v.neighbors.size(), 70u);
  const GradientDepthOptions thin;  // default level_min_step_deg
  ASSERT_GT(thin.level_min_step_deg, 0);
  GradientDepthOptions all = thin;
  all.level_min_step_deg = 0;
  const std::vector<char> grid = HierarchyGrid(SequenceViews(*v.sequence), thin);
  std::vector<ViewImage> on_grid = v.neighbors;
  std::vector<const ViewImage*> grid_ptrs;
  std::vector<const PinholeView*> nb_views;
  std::vector<char> nb_grid;
  for (size_t k = 0; k < on_grid.size(); ++k) {
    on_grid[k].on_grid = grid[v.neighbor_ids[k]];
    grid_ptrs.push_back(&on_grid[k]);
    nb_views.push_back(&on_grid[k].view);
    nb_grid.push_back(on_grid[k].on_grid);
  }
  const std::vector<int> used = SelectHierarchyViews(v.ref.view, nb_views, nb_grid, thin);
  EXPECT_EQ(SelectHierarchyViews(v.ref.view, nb_views, nb_grid, all).size(), v.neighbors.size());
  std::printf("views within 5°: %zu, used on the grid: %zu\n", v.neighbors.size(), used.size());
  EXPECT_LE(used.size(), 24u);
  EXPECT_GE(used.size(), 10u);
  // The first level is the nearest view on each side, on the grid or not.
  ASSERT_GE(used.size(), 2u);
  EXPECT_EQ(used[0], 0);
  // The farthest view used is nearly as far as the farthest within 5°.
  auto angle = [&](int k) {
    return std::acos(std::clamp(v.ref.view.ViewingDirection().dot(nb_views[k]->ViewingDirection()), -1.0, 1.0)) *
           180.0 / M_PI;
  };
  double far_used = 0, far_all = 0;
  for (int k : used) far_used = std::max(far_used, angle(k));
  for (size_t k = 0; k < nb_views.size(); ++k) far_all = std::max(far_all, angle(static_cast<int>(k)));
  EXPECT_GE(far_used, far_all - thin.level_min_step_deg);
  // Selecting among the selected views gives them again (StreamingDepth passes only those).
  std::vector<const PinholeView*> sub_views;
  std::vector<char> sub_grid;
  for (int k : used) {
    sub_views.push_back(nb_views[k]);
    sub_grid.push_back(nb_grid[k]);
  }
  EXPECT_EQ(SelectHierarchyViews(v.ref.view, sub_views, sub_grid, thin).size(), used.size());

  const auto s_all = ScoreDepth(v, GradientDepthEstimator(all).Estimate(v.ref, v.NeighborPtrs(), v.volume), true);
  const auto s_thin = ScoreDepth(v, GradientDepthEstimator(thin).Estimate(v.ref, grid_ptrs, v.volume), true);
  // Without the grid (a caller with no sequence): thinned relative to the reference.
  const auto s_local = ScoreDepth(v, GradientDepthEstimator(thin).Estimate(v.ref, v.NeighborPtrs(), v.volume), true);
  std::printf("dense sphere: all views %.4f/%.4f, grid %.4f/%.4f, local step %.4f/%.4f (accuracy/coverage)\n",
              s_all.Accuracy(), s_all.Coverage(), s_thin.Accuracy(), s_thin.Coverage(), s_local.Accuracy(),
              s_local.Coverage());
  ASSERT_GT(s_all.expected, 1000);
  EXPECT_GE(s_all.Accuracy(), 0.93);
  EXPECT_GE(s_thin.Accuracy(), s_all.Accuracy() - 0.01);
  EXPECT_GE(s_thin.Coverage(), s_all.Coverage() - 0.01);
  EXPECT_GE(s_local.Accuracy(), s_all.Accuracy() - 0.01);
}

TEST(GradientDepthEstimatorOptions, CheckRejectsBadValues) {
  GradientDepthOptions o;
  o.patch_length = 4;
  EXPECT_THROW(o.Check(), OptionError);
  o = GradientDepthOptions();
  o.sigma_c = 0;
  EXPECT_THROW(GradientDepthEstimator{o}, OptionError);
  o = GradientDepthOptions();
  o.level_min_step_deg = -1;
  EXPECT_THROW(o.Check(), OptionError);
  o.level_min_step_deg = o.max_view_angle_deg;
  EXPECT_THROW(o.Check(), OptionError);
  o = GradientDepthOptions();
  o.gradient_peak_fraction = 1.5;
  EXPECT_THROW(o.Check(), OptionError);
}

}  // namespace
}  // namespace lfrecon
