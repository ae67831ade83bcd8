#include "depth/depth_filter.h"

#include <gtest/gtest.h>

#include "depth/streaming_depth.h"
#include "synth_views.h"
#include "util/error.h"

namespace lfrecon {
namespace {

// Accuracy (within 0.5 %) over all foreground pixels with an estimate, edges included.
double Accuracy(const synth::RenderResult& truth, const cv::Mat& fg, const DepthMap& m, long long* n) {
  long long est = 0, ok = 0;
  for (int r = 0; r < m.depth.rows; ++r)
    for (int c = 0; c < m.depth.cols; ++c) {
      const double t = truth.depth.at<double>(r, c);
      const float e = m.depth.at<float>(r, c);
      if (!fg.at<std::uint8_t>(r, c) || !(t > 0) || !(e > 0)) continue;
      ++est;
      ok += std::abs(e - t) <= 0.005 * t;
    }
  *n = est;
  return est ? static_cast<double>(ok) / est : 0.0;
}

TEST(DepthFilter, RaisesAccuracyOnOcclusionScene) {
  synth::SynthOptions o;
  o.scene = "occlusion";
  o.frames = 240;  // 1.5° apart: ~3 views within 5°, ~10 within 15° on each side
  o.width = 320;
  o.height = 180;
  auto seq = std::make_shared<synth::SynthSequence>(synth::SynthSequence::Create(o));
  std::vector<PinholeView> views;
  for (int i = 0; i < seq->NumFrames(); ++i) views.push_back(seq->View(i));
  StreamingDepthOptions opt;
  opt.filter.voxel_size = 0.004;
  StreamingDepth stage(views, seq->scene().foreground_bbox(), opt);
  auto frames = seq->OpenFrames();
  const int ref = 12;
  DepthMap sparse, filtered;
  const StreamingDepthStats stats =
      stage.Run(*frames, {ref}, [&](int i, const cv::Mat&, const DepthMap& s, const DepthMap& f) {
        EXPECT_EQ(i, ref);
        sparse = s;
        filtered = f;
      });
  ASSERT_FALSE(filtered.depth.empty());
  const synth::RenderResult truth = seq->Render(ref);
  const cv::Mat fg = synth::ForegroundMask(seq->scene(), truth.labels);
  long long n_sparse = 0, n_filtered = 0;
  const double a_sparse = Accuracy(truth, fg, sparse, &n_sparse);
  const double a_filtered = Accuracy(truth, fg, filtered, &n_filtered);
  std::printf("occlusion: sparse accuracy %.4f (%lld px), filtered %.4f (%lld px); %d sparse maps, %d frames held\n",
              a_sparse, n_sparse, a_filtered, n_filtered, stats.sparse_maps, stats.max_frames_held);
  EXPECT_GT(n_sparse, 2000);
  EXPECT_GE(n_filtered, 0.9 * n_sparse);   // filtering moves, it rarely removes
  EXPECT_GT(a_filtered, a_sparse + 0.03);  // and it moves towards the truth
  EXPECT_GE(a_filtered, 0.7);
  // Background depths are kept as they are.
  for (int r = 0; r < sparse.depth.rows; ++r)
    for (int c = 0; c < sparse.depth.cols; ++c) {
      if (sparse.label.at<std::uint8_t>(r, c) == static_cast<std::uint8_t>(DepthLabel::kBackground)) {
        ASSERT_EQ(sparse.depth.at<float>(r, c), filtered.depth.at<float>(r, c));
      }
    }
}

TEST(VoteGrid, AddThenRemoveLeavesNoVotes) {
  const auto v = testing::MakeSynthViews("sphere", 0, 5.0, 160, 90, 480);
  const DepthMap m = GradientDepthEstimator(GradientDepthOptions()).Estimate(v.ref, v.NeighborPtrs(), v.volume);
  ASSERT_GT(m.CountValid(), 100);
  DepthFilterOptions o;
  o.grid_resolution = 64;
  VoteGrid grid(v.volume, o);
  grid.Splat(m, v.ref.view, 1.0f);
  // A foreground estimate's own point has votes.
  int checked = 0;
  for (int r = 0; r < m.depth.rows && checked < 50; ++r)
    for (int c = 0; c < m.depth.cols && checked < 50; ++c)
      if (m.label.at<std::uint8_t>(r, c) == static_cast<std::uint8_t>(DepthLabel::kForeground) &&
          m.confidence.at<float>(r, c) > 0.2f) {
        EXPECT_GT(grid.VotesAt(v.ref.view.Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), m.depth.at<float>(r, c))), 0.1f);
        ++checked;
      }
  EXPECT_EQ(checked, 50);
  grid.Splat(m, v.ref.view, -1.0f);
  for (double x = v.volume.min.x(); x < v.volume.max.x(); x += 0.01)
    for (double y = v.volume.min.y(); y < v.volume.max.y(); y += 0.01)
      for (double z = v.volume.min.z(); z < v.volume.max.z(); z += 0.01)
        ASSERT_NEAR(grid.VotesAt(Eigen::Vector3d(x, y, z)), 0.0f, 1e-3f);
}

TEST(DepthFilterOptions, Check) {
  DepthFilterOptions o;
  o.sigma_v_voxels = 0;
  EXPECT_THROW(o.Check(), OptionError);
  BoundingBox empty;
  EXPECT_THROW(VoteGrid(empty, DepthFilterOptions()), OptionError);
}

}  // namespace
}  // namespace lfrecon
