#include "synth/sequence.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cstdlib>

#include "synth/scenes.h"
#include "util/error.h"
#include "util/progress.h"

namespace lfrecon::synth {
namespace {

SynthOptions Small(const std::string& scene = "tabletop") {
  SynthOptions o;
  o.scene = scene;
  o.frames = 12;
  o.width = 128;
  o.height = 72;
  return o;
}

TEST(SynthSequence, CameraAndPosesFollowTheOptions) {
  SynthOptions o = Small();
  o.hfov_deg = 55;
  const SynthSequence seq = SynthSequence::Create(o);
  EXPECT_EQ(seq.NumFrames(), 12);
  EXPECT_EQ(seq.camera().model, CameraModelId::kPinhole);
  EXPECT_EQ(seq.camera().width, 128);
  EXPECT_NEAR(seq.camera().cx(), 64.0, 1e-12);  // COLMAP convention: cx = W / 2
  EXPECT_NEAR(seq.camera().cy(), 36.0, 1e-12);
  EXPECT_NEAR(seq.hfov_deg(), 55.0, 1e-9);
  const PinholeView v = seq.View(5);
  EXPECT_LT((v.Center() - CameraCenter(seq.cam_from_world(5))).norm(), 1e-12);
  EXPECT_EQ(SynthSequence::ImageName(42), "00042.png");
  EXPECT_EQ(SynthSequence::ImageName(7, "jpg"), "00007.jpg");
  // Helix defaults to three loops.
  o.path = PathType::kHelix;
  EXPECT_DOUBLE_EQ(SynthSequence::Create(o).path().loops, 3.0);
  o.loops = 2;
  EXPECT_DOUBLE_EQ(SynthSequence::Create(o).path().loops, 2.0);
}

TEST(SynthSequence, FrameAloneEqualsFrameInStream) {
  const SynthSequence seq = SynthSequence::Create(Small("occlusion"));
  std::unique_ptr<FrameSource> stream = seq.OpenFrames();
  ASSERT_EQ(stream->NumFrames(), 12);
  Frame f;
  int n = 0;
  while (stream->Next(&f)) {
    ASSERT_EQ(f.index, n);
    ASSERT_EQ(f.image.type(), CV_32FC3);
    if (n == 5 || n == 11) {
      // A fresh sequence and source, asked only for this frame.
      const SynthSequence again = SynthSequence::Create(Small("occlusion"));
      const Frame alone = again.OpenFrames()->Read(n);
      EXPECT_EQ(alone.name, f.name);
      EXPECT_EQ(cv::norm(alone.image, f.image, cv::NORM_INF), 0.0) << n;
      EXPECT_EQ(cv::norm(seq.RenderImage(n), f.image, cv::NORM_INF), 0.0) << n;
    }
    ++n;
  }
  EXPECT_EQ(n, 12);
  EXPECT_THROW(stream->Read(12), InputError);
  EXPECT_THROW(stream->Read(-1), InputError);
}

TEST(SynthSequence, CustomSceneAndPath) {
  Scene scene("custom");
  scene.Add(Primitive::Sphere({0, 0, 0.2}, 0.1, Material::Noise({0.1f, 0.1f, 0.1f}, {0.9f, 0.9f, 0.9f}, 0.01))
                .Foreground());
  BoundingBox V;
  V.min = Eigen::Vector3d(-0.11, -0.11, 0.09);
  V.max = Eigen::Vector3d(0.11, 0.11, 0.31);
  scene.set_foreground_bbox(V);
  CameraPathOptions path;
  path.num_frames = 6;
  path.target = Eigen::Vector3d(0, 0, 0.2);
  path.radius = 0.6;
  path.height = 0.4;
  const SynthSequence seq(scene, Camera::PinholeFromHfov(96, 54, 50), path, RenderOptions(), 3);
  const RenderResult r = seq.Render(2);
  EXPECT_GT(cv::countNonZero(r.labels == 0), 500);
  EXPECT_EQ(seq.GroundTruthMesh().vertices.empty(), false);
  EXPECT_THROW(seq.Render(6), std::out_of_range);
}

TEST(SynthSequence, BadOptionsAreOptionErrors) {
  SynthOptions o = Small();
  o.frames = 0;
  EXPECT_THROW(SynthSequence::Create(o), OptionError);
  o = Small("nope");
  EXPECT_THROW(SynthSequence::Create(o), OptionError);
  o = Small();
  o.render.supersampling = 0;
  EXPECT_THROW(SynthSequence::Create(o), OptionError);
  o = Small();
  o.hfov_deg = 190;
  EXPECT_THROW(SynthSequence::Create(o), OptionError);
}

// Speed measurement (not a pass/fail check): LFRECON_SYNTH_BENCH=1 renders a
// few tabletop frames at 640x360 and 1280x720 and records ms per frame.
TEST(SynthSequence, RenderSpeed) {
  if (!std::getenv("LFRECON_SYNTH_BENCH")) GTEST_SKIP() << "set LFRECON_SYNTH_BENCH=1 to measure";
  const char* threads = std::getenv("LFRECON_SYNTH_BENCH_THREADS");
  const int n_threads = threads ? std::atoi(threads) : 2;
  tbb::global_control limit(tbb::global_control::max_allowed_parallelism,
                            static_cast<std::size_t>(n_threads));
  for (auto [w, h] : {std::pair{640, 360}, std::pair{1280, 720}}) {
    SynthOptions o;
    o.frames = 3000;
    o.width = w;
    o.height = h;
    o.path = PathType::kHandheld;
    const SynthSequence seq = SynthSequence::Create(o);
    seq.Render(0);  // warm-up
    const int n = 10;
    Timer timer;
    for (int i = 0; i < n; ++i) seq.Render(i * 300);
    const double ms = 1000.0 * timer.Seconds() / n;
    std::printf("render %dx%d, %d threads: %.1f ms/frame\n", w, h, n_threads, ms);
    RecordProperty("ms_per_frame_" + std::to_string(w) + "x" + std::to_string(h), std::to_string(ms));
  }
}

}  // namespace
}  // namespace lfrecon::synth
