#include "depth/streaming_depth.h"

#include <gtest/gtest.h>

#include "geometry/view_graph.h"
#include "synth/sequence.h"
#include "util/error.h"

namespace lfrecon {
namespace {

std::shared_ptr<synth::SynthSequence> SmallSequence(int frames) {
  synth::SynthOptions o;
  o.scene = "sphere";
  o.frames = frames;
  o.width = 96;
  o.height = 54;
  return std::make_shared<synth::SynthSequence>(synth::SynthSequence::Create(o));
}

// The sequence's views and their viewing directions.
std::pair<std::vector<PinholeView>, std::vector<Eigen::Vector3d>> ViewsAndDirections(const synth::SynthSequence& seq) {
  std::pair<std::vector<PinholeView>, std::vector<Eigen::Vector3d>> out;
  for (int i = 0; i < seq.NumFrames(); ++i) {
    out.first.push_back(seq.View(i));
    out.second.push_back(out.first.back().ViewingDirection());
  }
  return out;
}

TEST(StreamingDepth, EmitsEveryWantedViewOnceWithBoundedWindow) {
  const auto seq = SmallSequence(360);  // 1° apart: ~10 within 5°, ~30 within 15°
  std::vector<PinholeView> views;
  for (int i = 0; i < seq->NumFrames(); ++i) views.push_back(seq->View(i));
  StreamingDepth stage(views, seq->scene().foreground_bbox(), StreamingDepthOptions());
  auto frames = seq->OpenFrames();
  std::vector<int> wanted = {40, 41, 100, 200};
  std::vector<int> emitted;
  const auto stats = stage.Run(*frames, wanted, [&](int i, const cv::Mat& image, const DepthMap& s, const DepthMap& f) {
    emitted.push_back(i);
    EXPECT_EQ(image.size(), cv::Size(96, 54));
    EXPECT_EQ(s.depth.size(), image.size());
    EXPECT_EQ(f.depth.size(), image.size());
    EXPECT_GT(s.CountValid(), 0);
  });
  std::sort(emitted.begin(), emitted.end());
  EXPECT_EQ(emitted, wanted);
  // Only what the pending views need is held: never the whole sequence.
  EXPECT_LE(stats.max_frames_held, 40);
  EXPECT_LE(stats.max_sparse_held, 70);
  EXPECT_LE(stats.frames_read, 240);  // stops after the last frame any wanted view needs
  EXPECT_EQ(stats.filtered_maps, 4);
}

TEST(StreamingDepth, MaxFrameGapStopsTheFirstViewsWaitingForTheEndOfTheLoop) {
  const auto seq = SmallSequence(360);  // one closed loop, 1° apart
  std::vector<PinholeView> views;
  for (int i = 0; i < seq->NumFrames(); ++i) views.push_back(seq->View(i));
  for (int gap : {0, 60}) {
    StreamingDepthOptions o;
    o.max_frame_gap = gap;
    StreamingDepth stage(views, seq->scene().foreground_bbox(), o);
    auto frames = seq->OpenFrames();
    int emitted = 0;
    const auto stats = stage.Run(*frames, {0, 1}, [&](int, const cv::Mat&, const DepthMap& s, const DepthMap&) {
      ++emitted;
      EXPECT_GT(s.CountValid(), 0);
    });
    EXPECT_EQ(emitted, 2);
    // Without the gap view 0's neighbours across the seam (frames 345-359) are
    // waited for; with it view 0 is done within ~20 frames (15° ahead plus 5°).
    if (gap == 0) EXPECT_EQ(stats.frames_read, 360);
    else EXPECT_LE(stats.frames_read, 25);
  }
}

TEST(StreamingDepth, DenseSequenceHoldsOnlyTheHierarchyGrid) {
  // 3000 frames per loop (0.12° apart): ~100 frames within 5° of a view. On
  // the hierarchy grid (level_min_step_deg) the sparse maps use, and the
  // stage holds, a fraction of them; every frame within 5° is still tapped
  // before its view is emitted.
  const auto seq = SmallSequence(3000);
  const auto [views, dirs] = ViewsAndDirections(*seq);
  const ViewGraph near(dirs, 5.0);
  const std::vector<int> wanted = {150, 160};
  auto run = [&](double step, std::vector<int>* emitted) {
    StreamingDepthOptions o;
    o.run_filter = false;
    o.gradient.level_min_step_deg = step;
    StreamingDepth stage(views, seq->scene().foreground_bbox(), o);
    std::vector<char> tapped(views.size(), 0);
    stage.SetFrameTap([&](int f, const ViewImage&, const cv::Mat&) { tapped[f] = 1; });
    auto frames = seq->OpenFrames();
    const auto stats = stage.Run(*frames, wanted, [&](int i, const cv::Mat&, const DepthMap& s, const DepthMap&) {
      emitted->push_back(i);
      EXPECT_GT(s.CountValid(), 0);
      for (int j : near.Neighbors(i)) EXPECT_TRUE(tapped[j]) << "view " << i << " emitted before frame " << j;
    });
    return stats;
  };
  std::vector<int> emitted_all, emitted_thin;
  const auto all = run(0.0, &emitted_all);
  const auto thin = run(GradientDepthOptions().level_min_step_deg, &emitted_thin);
  std::printf("frames held: %d (all views within 5°), %d (grid); neighbours per map %.1f, %.1f\n",
              all.max_frames_held, thin.max_frames_held, all.neighbors_used / 2.0, thin.neighbors_used / 2.0);
  EXPECT_EQ(emitted_all.size(), 2u);
  EXPECT_EQ(emitted_thin.size(), 2u);
  EXPECT_GE(all.neighbors_used / 2, 70);
  EXPECT_LE(thin.neighbors_used / 2, 24);
  EXPECT_GE(all.max_frames_held, 70);
  EXPECT_LE(thin.max_frames_held, 40);
  EXPECT_EQ(thin.frames_read, all.frames_read);  // the tap contract: every frame within 5° is read
}

TEST(StreamingDepth, FilterVotersAreTheGridViewsWithin15Degrees) {
  for (int frames : {480, 3000}) {  // 0.75° apart: every view votes; 0.12°: the grid (≥ 0.5°) only
    const auto seq = SmallSequence(frames);
    const auto [views, dirs] = ViewsAndDirections(*seq);
    const ViewGraph wide(dirs, DepthFilterOptions().max_view_angle_deg);
    const std::vector<char> grid = HierarchyGrid(views, GradientDepthOptions());
    const std::vector<int> voters = FilterVoters(wide, grid, frames / 2);
    std::printf("%d frames: %zu views within 15°, %zu voters\n", frames, wide.Neighbors(frames / 2).size(),
                voters.size());
    if (frames == 480) {
      EXPECT_EQ(voters, wide.Neighbors(frames / 2));
    } else {
      EXPECT_GE(wide.Neighbors(frames / 2).size(), 200u);
      EXPECT_LE(voters.size(), 70u);
      EXPECT_GE(voters.size(), 40u);
      for (int j : voters) EXPECT_TRUE(grid[j]);
    }
  }
}

TEST(StreamingDepth, VoterStepMakesTheSpacedViewsTheOnlyVoters) {
  // 1200 frames a loop: 0.3° apart. Voters at least 1° apart are every fourth
  // view (SpacedAtLeast, as the plan's view selection), with or without the
  // hierarchy grid (0.5°, every second view), and only they and the wanted
  // views need sparse maps.
  const auto seq = SmallSequence(1200);
  const auto [views, dirs] = ViewsAndDirections(*seq);
  const std::vector<char> spaced = SpacedAtLeast(dirs, 1.0);
  std::vector<int> wanted;
  for (int i = 0; i < 1200; ++i)
    if (spaced[i] && i >= 300 && i < 340) wanted.push_back(i);
  ASSERT_EQ(wanted.size(), 10u);
  for (bool hierarchy : {true, false}) {
    StreamingDepthOptions o;
    o.gradient.use_hierarchy = hierarchy;
    o.voter_min_step_deg = 1.0;
    const DepthPlan plan = PlanDepth(views, o, wanted);
    for (int i : wanted) {
      EXPECT_GE(plan.voters[i].size(), 20u) << i;  // ±15° at 1.2°: ~25 (the view itself is no voter)
      EXPECT_LE(plan.voters[i].size(), 26u) << i;
      for (int j : plan.voters[i]) EXPECT_TRUE(spaced[j]) << "view " << i << " voter " << j << " hierarchy " << hierarchy;
    }
    for (int s = 0; s < 1200; ++s) {
      if (plan.need_sparse[s]) {
        EXPECT_TRUE(spaced[s]) << s << " hierarchy " << hierarchy;
      }
    }
  }
}

TEST(StreamingDepth, ShortStreamAndBadIndexAreErrors) {
  const auto seq = SmallSequence(120);
  std::vector<PinholeView> views;
  for (int i = 0; i < seq->NumFrames(); ++i) views.push_back(seq->View(i));
  StreamingDepth stage(views, seq->scene().foreground_bbox(), StreamingDepthOptions());
  auto frames = seq->OpenFrames();
  EXPECT_THROW(stage.Run(*frames, {500}, [](int, const cv::Mat&, const DepthMap&, const DepthMap&) {}), OptionError);
  // More views than the stream has frames.
  views.insert(views.end(), views.begin(), views.end());
  StreamingDepth longer(views, seq->scene().foreground_bbox(), StreamingDepthOptions());
  auto frames2 = seq->OpenFrames();
  EXPECT_THROW(longer.Run(*frames2, {200}, [](int, const cv::Mat&, const DepthMap&, const DepthMap&) {}), InputError);
}

}  // namespace
}  // namespace lfrecon
