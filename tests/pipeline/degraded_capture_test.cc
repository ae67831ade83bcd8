// A generated loop seen as a hand-held capture would give it (sensor noise,
// JPEG, exposure drift, per-frame pose error) reconstructs nearly as well as
// its clean twin once the poses are refined; with the given poses as they are
// it does not (what the refinement is for). 72 frames of 192x108 over a
// quarter loop, so the three reconstructions take about a minute.
#include <gtest/gtest.h>

#include "eval/mesh_metrics.h"
#include "pipeline/embedded_pipeline.h"
#include "pipeline/jpeg_source.h"
#include "pipeline/quarter_loop.h"
#include "poses/pose_refinement.h"
#include "synth/sequence.h"

namespace lfrecon {
namespace {

synth::SynthSequence Loop(bool degraded) {
  synth::SynthOptions o = testing::TabletopQuarterLoop();
  o.render.noise_sigma = degraded ? 0.01 : 0.005;
  if (degraded) {
    o.degradation.exposure_drift = 0.04;
    // At 192 px wide a pixel is 3.3x the figurines' (640 px): the pose error
    // is scaled with it, so it moves points by the same share of a pixel.
    o.degradation.pose_rotation_deg = 0.066;
    o.degradation.pose_translation_mm = 1.6;
  }
  return synth::SynthSequence::Create(o);
}

struct Outcome {
  double f5 = 0, precision = 0, recall = 0;
};

Outcome Reconstruct(const synth::SynthSequence& seq, bool degraded, bool refine_poses) {
  std::vector<PinholeView> views;
  for (int i = 0; i < seq.NumFrames(); ++i) views.emplace_back(seq.camera(), seq.given_cam_from_world(i));
  auto source = [&]() -> std::unique_ptr<FrameSource> {
    if (degraded) return std::make_unique<JpegSource>(seq.OpenFrames(), 80);
    return seq.OpenFrames();
  };
  if (refine_poses) {
    auto frames = source();
    views = RefinePoses(*frames, views, PoseRefinementOptions{}).views;
  }
  PipelineOptions options;
  options.color_views = 0;
  EmbeddedPipeline pipeline(views, seq.scene().foreground_bbox(), options);
  auto frames = source();
  const PipelineResult r = pipeline.Run(*frames);
  MeshMetricsOptions mo;
  mo.thresholds = {0.005};
  mo.volume = seq.scene().foreground_bbox();
  const MeshMetrics m = EvaluateMesh(r.mesh, seq.GroundTruthMesh(), nullptr, mo);
  return {m.scores[0].fscore, m.scores[0].precision, m.scores[0].recall};
}

TEST(DegradedCapture, RefinedPosesComeCloseToTheCleanTwin) {
  const synth::SynthSequence clean = Loop(false), degraded = Loop(true);
  const Outcome c = Reconstruct(clean, false, false);
  const Outcome given = Reconstruct(degraded, true, false);
  const Outcome refined = Reconstruct(degraded, true, true);
  std::printf("F@5mm (P/R): clean %.3f (%.3f/%.3f), degraded with given poses %.3f (%.3f/%.3f), with refined poses "
              "%.3f (%.3f/%.3f)\n",
              c.f5, c.precision, c.recall, given.f5, given.precision, given.recall, refined.f5, refined.precision,
              refined.recall);
  // Measured (2026-12-01): clean 0.513, given poses 0.037, refined 0.334. At
  // this size the refined poses still cost 0.18 (on the figurines at 640x360
  // the same degradation costs 0.006 once refined: docs/benchmarks.md).
  EXPECT_GT(c.f5, 0.45);
  EXPECT_GT(refined.f5, c.f5 - 0.25);
  EXPECT_GT(refined.f5, given.f5 + 0.2);
}

}  // namespace
}  // namespace lfrecon
