// The reconstruction plan on generated camera paths: neighbour counts, on_grid
// flags and view selection against hand-computed expectations.
#include "pipeline/reconstruction_plan.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "pipeline/pipeline_flags.h"
#include "util/error.h"

namespace lfrecon {
namespace {

// `n` cameras on a horizontal circle (radius 1 m) around the origin, looking at
// it, `step_deg` apart in azimuth: consecutive viewing directions differ by step_deg.
std::vector<PinholeView> Arc(int n, double step_deg) {
  std::vector<PinholeView> out;
  for (int k = 0; k < n; ++k) {
    const double a = k * step_deg * M_PI / 180.0;
    const Eigen::Vector3d c(std::cos(a), std::sin(a), 0.0);
    const Eigen::Vector3d z = -c;  // forward
    const Eigen::Vector3d up(0, 0, 1);
    const Eigen::Vector3d x = z.cross(-up).normalized();
    const Eigen::Vector3d y = z.cross(x);
    PinholeView v;
    v.width = 160;
    v.height = 90;
    v.K << 150, 0, 80, 0, 150, 45, 0, 0, 1;
    v.K_inv = v.K.inverse();
    v.R.row(0) = x.transpose();
    v.R.row(1) = y.transpose();
    v.R.row(2) = z.transpose();
    v.t = -v.R * c;
    out.push_back(v);
  }
  return out;
}

BoundingBox Box() {
  BoundingBox b;
  b.min = Eigen::Vector3d(-0.2, -0.2, -0.2);
  b.max = Eigen::Vector3d(0.2, 0.2, 0.2);
  return b;
}

// 0.35° apart (under the hierarchy grid's 0.5°): the grid and the selection are
// the even views (view 0, then the first view >= 0.5° from the last kept: 0.7°).
// For an even view s far from the ends, by hand:
//  * within 5° of it: s±1 .. s±14 (14 × 0.35 = 4.9°), 28 frames;
//  * depth neighbours: the first level s-1, s+1; then per side the grid views
//    >= 0.5° from the last one used: s∓2 is 0.35° from s∓1 (no), s∓4 .. s∓14 are
//    (1.05°, then 0.7° apart): 6 per side, 2 + 12 = 14 (not 28: the service's
//    workers, which left on_grid unset, read every frame within 5°);
//  * voters: the even views within 15° (42 × 0.35 = 14.7°), 21 per side, 42;
//  * photoconsistency neighbours: the 28 frames within 5°.
TEST(ReconstructionPlan, DenseArcNeighboursAndGridAgainstHandCounts) {
  const std::vector<PinholeView> cams = Arc(200, 0.35);
  PipelineOptions o;
  o.depth.max_frame_gap = 0;
  o.selection.min_step_deg = 0.5;  // the hand counts below are for a 0.5° selection (the default is 2°)
  const ReconstructionPlan plan = ReconstructionPlan::Compute(cams, Box(), o);
  ASSERT_EQ(plan.num_views(), 200);
  for (int k = 0; k < 200; ++k) {
    EXPECT_EQ(plan.OnGrid(k), k % 2 == 0) << k;
    EXPECT_EQ(plan.Selected(k), k % 2 == 0) << k;
    EXPECT_EQ(plan.NeedsSparse(k), k % 2 == 0) << k;
  }
  EXPECT_EQ(plan.views.size(), 100u);
  const int s = 100;
  const std::vector<int>& nb = plan.DepthNeighbours(s);
  ASSERT_EQ(nb.size(), 14u);
  // The first level: the nearest view, then the other side's nearest.
  EXPECT_EQ(std::min(nb[0], nb[1]), 99);
  EXPECT_EQ(std::max(nb[0], nb[1]), 101);
  std::vector<int> later(nb.begin() + 2, nb.end());
  std::sort(later.begin(), later.end());
  EXPECT_EQ(later, (std::vector<int>{86, 88, 90, 92, 94, 96, 104, 106, 108, 110, 112, 114}));
  EXPECT_EQ(plan.Voters(s).size(), 42u);
  EXPECT_EQ(plan.Voters(s).front(), 58);
  EXPECT_EQ(plan.Voters(s).back(), 142);
  for (int j : plan.Voters(s)) EXPECT_EQ(j % 2, 0);
  // Photoconsistency neighbours: the grid's frames within 5° (14 per side before
  // docs/benchmarks.md "Photoconsistency neighbours on the grid", 7 now).
  EXPECT_EQ(plan.PhotoNeighbours(s).size(), 14u);
  for (int j : plan.PhotoNeighbours(s)) EXPECT_EQ(j % 2, 0) << j;
  EXPECT_EQ(plan.depth.read_before_emit[s], 114);
  // Views not selected have no entries; an end view has one side only.
  EXPECT_TRUE(plan.DepthNeighbours(101).empty());
  EXPECT_TRUE(plan.PhotoNeighbours(101).empty());
  EXPECT_EQ(plan.DepthNeighbours(0).size(), 1u + 6u);  // view 1, then 4 .. 14
  // Colour and carving frames: evenly spread over the selected views.
  EXPECT_EQ(plan.color_frames, (std::vector<int>{0, 24, 50, 74, 100, 124, 150, 174}));
  EXPECT_EQ(plan.carving_frames.size(), 24u);
  for (int f : plan.carving_frames) EXPECT_TRUE(plan.Selected(f));
  EXPECT_DOUBLE_EQ(plan.fusion.voxel_size, 0.4 / 256);
}

TEST(ReconstructionPlan, ViewSelectionCounts) {
  PipelineOptions o;
  // 0.25° apart: every eighth view (2°, exactly the step: kept up to rounding).
  EXPECT_EQ(ReconstructionPlan::Compute(Arc(240, 0.25), Box(), o).views.size(), 30u);
  // 0.12° (a 3000-frame loop's spacing): every 17th (2.04°), 1.92° being short of 2°.
  const ReconstructionPlan p12 = ReconstructionPlan::Compute(Arc(300, 0.12), Box(), o);
  EXPECT_EQ(p12.views.size(), 18u);
  EXPECT_EQ(p12.views[1], 17);
  // 0.75° (figurines): every third (2.25°); 1.5° (the demo): every second (3°); 2.5°: every view.
  EXPECT_EQ(ReconstructionPlan::Compute(Arc(100, 0.75), Box(), o).views.size(), 34u);
  EXPECT_EQ(ReconstructionPlan::Compute(Arc(100, 1.5), Box(), o).views.size(), 50u);
  EXPECT_EQ(ReconstructionPlan::Compute(Arc(100, 2.5), Box(), o).views.size(), 100u);
  // 1° (the default before docs/benchmarks.md "View step 2°"): every ninth of the
  // 0.12° loop (1.08°); 0.5° (before "Fewer views, relative vote saturation"): every fifth (0.6°).
  o.selection.min_step_deg = 1.0;
  EXPECT_EQ(ReconstructionPlan::Compute(Arc(300, 0.12), Box(), o).views.size(), 34u);
  o.selection.min_step_deg = 0.5;
  EXPECT_EQ(ReconstructionPlan::Compute(Arc(300, 0.12), Box(), o).views.size(), 60u);
  // A smaller step keeps more; selection off keeps all.
  o.selection.min_step_deg = 0.25;
  EXPECT_EQ(ReconstructionPlan::Compute(Arc(300, 0.12), Box(), o).views.size(), 100u);  // every third (0.36°)
  o.selection.enabled = false;
  EXPECT_EQ(ReconstructionPlan::Compute(Arc(300, 0.12), Box(), o).views.size(), 300u);
  // The flag mapping: --all-views turns it off; given views win over selection.
  ReconstructionFlags f;
  EXPECT_TRUE(OptionsFromFlags(f).selection.enabled);
  f.all_views = true;
  EXPECT_FALSE(OptionsFromFlags(f).selection.enabled);
  PipelineOptions given;
  given.views = {7, 3, 3};
  EXPECT_EQ(ReconstructionPlan::Compute(Arc(20, 0.1), Box(), given).views, (std::vector<int>{3, 7}));
  given.views = {20};
  EXPECT_THROW(ReconstructionPlan::Compute(Arc(20, 0.1), Box(), given), OptionError);
  PipelineOptions bad;
  bad.selection.min_step_deg = -1;
  EXPECT_THROW(bad.Check(), OptionError);
}

// Where views are >= 0.5° apart the grid holds every view and the depth
// neighbours are every view within 5° (0.8°: 6 per side, 12). The default 2°
// selection keeps every third view (2.4°), and the filter's voters are the
// selected views within 15° (6 per side, 12): no other view needs a sparse map.
TEST(ReconstructionPlan, SparseSequenceUsesEveryViewWithin5Degrees) {
  const ReconstructionPlan plan = ReconstructionPlan::Compute(Arc(100, 0.8), Box(), PipelineOptions());
  for (int k = 0; k < 100; ++k) {
    EXPECT_TRUE(plan.OnGrid(k)) << k;
    EXPECT_EQ(plan.Selected(k), k % 3 == 0) << k;
    EXPECT_EQ(plan.NeedsSparse(k), k % 3 == 0) << k;
  }
  EXPECT_EQ(plan.DepthNeighbours(51).size(), 12u);
  EXPECT_EQ(plan.Voters(51).size(), 12u);
  for (int j : plan.Voters(51)) EXPECT_EQ(j % 3, 0) << j;
  EXPECT_EQ(plan.PhotoNeighbours(51).size(), 12u);
}

// Growing with the stream: on a closed dense loop (0.35° apart, 1029 frames, so
// the last views come back within every stage's angle of the first), Compute on
// every prefix agrees with Compute on the whole loop on each frame SettledFrames
// calls final; some frame of a prefix that it does not call final disagrees,
// so the comparison sees a truncated neighbourhood.
TEST(ReconstructionPlan, PrefixPlanAgreesWithFullPlanOnSettledFrames) {
  const int n = 1029;  // 360 / 0.35
  const std::vector<PinholeView> cams = Arc(n, 0.35);
  PipelineOptions o;
  o.depth.max_frame_gap = 30;
  const ReconstructionPlan full = ReconstructionPlan::Compute(cams, Box(), o);
  const auto same = [&](const ReconstructionPlan& a, int i) {
    const auto at = [i](const auto& v) { return v.at(static_cast<std::size_t>(i)); };
    return at(a.selected) == at(full.selected) && at(a.depth.on_grid) == at(full.depth.on_grid) &&
           at(a.depth.need_sparse) == at(full.depth.need_sparse) && at(a.depth.uses) == at(full.depth.uses) &&
           at(a.depth.voters) == at(full.depth.voters) && at(a.photo) == at(full.photo) &&
           at(a.depth.read_before_emit) == at(full.depth.read_before_emit);
  };
  int checked = 0, known_total = 0;
  for (int p : {1, 30, 60, 61, 100, 200, 400, 700, 999, 1028}) {
    const std::vector<PinholeView> prefix(cams.begin(), cams.begin() + p);
    const ReconstructionPlan part = ReconstructionPlan::Compute(prefix, Box(), o);
    const int settled = ReconstructionPlan::SettledFrames(p, false, o);
    EXPECT_EQ(settled, std::max(0, p - 60)) << p;
    for (int i = 0; i < settled; ++i) {
      EXPECT_TRUE(same(part, i)) << "prefix " << p << " frame " << i;
      ++checked;
    }
    if (p >= 30) {
      bool all_same = true;
      for (int i = settled; i < p; ++i) all_same = all_same && same(part, i);
      EXPECT_FALSE(all_same) << "prefix " << p;
    }
    // The order the views are processed in: the prefix's final part is the whole loop's
    // (a view is emitted up to 2 gaps after its frame: none is final before ~4 gaps).
    const int known = part.FinalOrder(false, o);
    EXPECT_TRUE(std::equal(part.order.begin(), part.order.begin() + known, full.order.begin())) << p;
    known_total += known;
  }
  EXPECT_GT(checked, 3000);
  EXPECT_GT(known_total, 0);
  EXPECT_EQ(full.FinalOrder(true, o), static_cast<int>(full.order.size()));
  EXPECT_EQ(full.order.size(), full.views.size());
  // Ended: every frame; unbounded gap or given views: none before the end.
  EXPECT_EQ(ReconstructionPlan::SettledFrames(n, true, o), n);
  PipelineOptions unbounded = o;
  unbounded.depth.max_frame_gap = 0;
  EXPECT_EQ(ReconstructionPlan::SettledFrames(500, false, unbounded), 0);
  EXPECT_EQ(ReconstructionPlan::SettledFrames(500, true, unbounded), 500);
  PipelineOptions given = o;
  given.views = {3};
  EXPECT_EQ(ReconstructionPlan::SettledFrames(500, false, given), 0);
}

// The depth stage settles one gap earlier: on a prefix, the frames below
// SettledDepthFrames have the full plan's need_sparse and depth neighbours, and
// every received frame has the full plan's selection and on_grid flag (what a
// worker reads for any frame it is given). A rule settling 2 frames more than
// that disagrees somewhere.
TEST(ReconstructionPlan, PrefixPlanAgreesWithFullPlanOnDepthSettledFrames) {
  const int n = 1029;
  const std::vector<PinholeView> cams = Arc(n, 0.35);
  PipelineOptions o;
  o.depth.max_frame_gap = 30;
  const ReconstructionPlan full = ReconstructionPlan::Compute(cams, Box(), o);
  const auto same_depth = [&](const ReconstructionPlan& a, int i) {
    const auto at = [i](const auto& v) { return v.at(static_cast<std::size_t>(i)); };
    return at(a.depth.need_sparse) == at(full.depth.need_sparse) && at(a.depth.uses) == at(full.depth.uses);
  };
  int checked = 0, greedy = 0, beyond = 0;
  for (int p : {1, 30, 31, 45, 100, 200, 400, 700, 999, 1028}) {
    const std::vector<PinholeView> prefix(cams.begin(), cams.begin() + p);
    const ReconstructionPlan part = ReconstructionPlan::Compute(prefix, Box(), o);
    const int settled = ReconstructionPlan::SettledDepthFrames(p, false, o);
    EXPECT_EQ(settled, std::max(0, p - 30)) << p;
    EXPECT_LE(ReconstructionPlan::SettledFrames(p, false, o), settled) << p;
    for (int i = 0; i < settled; ++i, ++checked) EXPECT_TRUE(same_depth(part, i)) << "prefix " << p << " frame " << i;
    for (int i = 0; i < p; ++i, ++greedy) {
      EXPECT_EQ(part.selected[i], full.selected[i]) << "prefix " << p << " frame " << i;
      EXPECT_EQ(part.depth.on_grid[i], full.depth.on_grid[i]) << "prefix " << p << " frame " << i;
    }
    for (int i = settled; i < std::min(p, settled + 2); ++i) beyond += !same_depth(part, i);
  }
  EXPECT_GT(checked, 3000);
  EXPECT_GT(greedy, 3500);
  EXPECT_GT(beyond, 0);
  EXPECT_EQ(ReconstructionPlan::SettledDepthFrames(n, true, o), n);
  PipelineOptions unbounded = o;
  unbounded.depth.max_frame_gap = 0;
  EXPECT_EQ(ReconstructionPlan::SettledDepthFrames(500, false, unbounded), 0);
  PipelineOptions given = o;
  given.views = {3};
  EXPECT_EQ(ReconstructionPlan::SettledDepthFrames(500, false, given), 0);
}

// --max-frame-gap: the flag sets the bound (0: none); a negative one is refused.
TEST(ReconstructionPlan, MaxFrameGapFlag) {
  ReconstructionFlags f;
  EXPECT_EQ(OptionsFromFlags(f).depth.max_frame_gap, StreamingDepthOptions{}.max_frame_gap);
  f.max_frame_gap = 40;
  EXPECT_EQ(OptionsFromFlags(f).depth.max_frame_gap, 40);
  f.max_frame_gap = 0;
  EXPECT_EQ(OptionsFromFlags(f).depth.max_frame_gap, 0);
  f.max_frame_gap = -1;
  EXPECT_THROW(OptionsFromFlags(f), OptionError);
}

// --chroma-weight: sets ρ's chroma weight (unset: the default); outside [0, 1] is refused.
TEST(ReconstructionPlan, ChromaWeightFlag) {
  ReconstructionFlags f;
  EXPECT_EQ(OptionsFromFlags(f).propagation.photo.chroma_weight, PhotoconsistencyOptions{}.chroma_weight);
  f.chroma_weight = 0.25;
  EXPECT_EQ(OptionsFromFlags(f).propagation.photo.chroma_weight, 0.25);
  f.chroma_weight = 1.5;
  EXPECT_THROW(OptionsFromFlags(f), OptionError);
}

// --view-step-deg: sets the selection's step (unset: the default); outside (0, 90) or with
// --all-views is refused.
TEST(ReconstructionPlan, ViewStepFlag) {
  ReconstructionFlags f;
  EXPECT_EQ(OptionsFromFlags(f).selection.min_step_deg, ViewSelectionOptions{}.min_step_deg);
  f.view_step_deg = 2.0;
  const PipelineOptions o = OptionsFromFlags(f);
  EXPECT_EQ(o.selection.min_step_deg, 2.0);
  // 0.75° apart (the figurines): every third view (2.25°).
  EXPECT_EQ(ReconstructionPlan::Compute(Arc(99, 0.75), Box(), o).views.size(), 33u);
  f.view_step_deg = 0;
  EXPECT_THROW(OptionsFromFlags(f), OptionError);
  f.view_step_deg = 90;
  EXPECT_THROW(OptionsFromFlags(f), OptionError);
  f.view_step_deg = 2.0;
  f.all_views = true;
  EXPECT_THROW(OptionsFromFlags(f), OptionError);
}

}  // namespace
}  // namespace lfrecon
