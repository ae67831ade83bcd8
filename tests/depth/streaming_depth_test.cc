#include "depth/streaming_depth.h"

#include <gtest/gtest.h>

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
