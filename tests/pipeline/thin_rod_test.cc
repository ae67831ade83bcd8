// A thin rod (1.8 mm radius, ~1.3 px wide here) standing before a strongly
// textured floor and dome: the reconstruction keeps the rod (thin recall) and
// adds no surface coloured like the background around it (precision inside V,
// the rod's 6 x 6 cm column, where a halo or a fin of background texture
// fused as surface would land). Clean frames and a degraded copy (noise,
// JPEG, exposure drift, pose error, refined poses), 64 frames of 320x180
// over a fifth of a loop (1.1° apart).
#include <gtest/gtest.h>

#include <cstdio>

#include "eval/mesh_metrics.h"
#include "pipeline/embedded_pipeline.h"
#include "pipeline/jpeg_source.h"
#include "poses/pose_refinement.h"
#include "synth/sequence.h"

namespace lfrecon {
namespace {

synth::SynthSequence Rod(bool degraded) {
  synth::SynthOptions o;
  o.scene = "thin_cylinder";
  o.frames = 64;
  o.loops = 0.2;
  o.width = 320;
  o.height = 180;
  o.render.noise_sigma = degraded ? 0.01 : 0.005;
  if (degraded) {
    o.degradation.exposure_drift = 0.04;
    // At 320 px a pixel is twice the figurines' (640 px): the figurines-noisy
    // pose error scaled with it.
    o.degradation.pose_rotation_deg = 0.04;
    o.degradation.pose_translation_mm = 1.0;
  }
  return synth::SynthSequence::Create(o);
}

struct Outcome {
  double precision = 0, recall = 0, thin_recall = 0;
  double precision_10mm = 0;
  std::size_t triangles = 0;
};

Outcome Reconstruct(const synth::SynthSequence& seq, bool degraded) {
  std::vector<PinholeView> views;
  for (int i = 0; i < seq.NumFrames(); ++i) views.emplace_back(seq.camera(), seq.given_cam_from_world(i));
  auto source = [&]() -> std::unique_ptr<FrameSource> {
    if (degraded) return std::make_unique<JpegSource>(seq.OpenFrames(), 80);
    return seq.OpenFrames();
  };
  if (degraded) {
    auto frames = source();
    views = RefinePoses(*frames, views, PoseRefinementOptions{}).views;
  }
  PipelineOptions options;
  options.color_views = 0;
  EmbeddedPipeline pipeline(views, seq.scene().foreground_bbox(), options);
  auto frames = source();
  const PipelineResult r = pipeline.Run(*frames);
  MeshMetricsOptions mo;
  mo.thresholds = {0.005, 0.010};
  mo.volume = seq.scene().foreground_bbox();
  const TriangleMesh thin = seq.GroundTruthMesh(true);
  const MeshMetrics m = EvaluateMesh(r.mesh, seq.GroundTruthMesh(), &thin, mo);
  return {m.scores[0].precision, m.scores[0].recall, m.scores[0].thin_recall, m.scores[1].precision,
          r.mesh.triangles.size()};
}

TEST(ThinRod, KeptWithoutBackgroundSheetsCleanAndDegraded) {
  const Outcome clean = Reconstruct(Rod(false), false);
  const Outcome degraded = Reconstruct(Rod(true), true);
  std::printf("thin rod @5mm: clean P %.3f R %.3f thin R %.3f (P@10 %.3f, %zu triangles); degraded P %.3f R %.3f "
              "thin R %.3f (P@10 %.3f, %zu triangles)\n",
              clean.precision, clean.recall, clean.thin_recall, clean.precision_10mm, clean.triangles,
              degraded.precision, degraded.recall, degraded.thin_recall, degraded.precision_10mm, degraded.triangles);
  // Measured 2026-12-02: clean P 0.999, thin R 0.404; degraded P 0.995, thin
  // R 0.356 (the rod is ~1.3 px wide here). 2026-12-03, with the consistency
  // along the edge (PhotoconsistencyOptions::centre_consistency): clean P
  // 0.997, thin R 0.713; degraded P 0.902 (P@10 1.000), thin R 0.608. A
  // background-coloured sheet or halo around the rod lies farther than 10 mm
  // from it and drops P@10 below 0.95 (V is the rod's 6 cm column); the
  // degraded rod's own noisy depths thicken it along the views' mean
  // direction (a fifth of a loop constrains depth least) to 5-6.4 mm from
  // its surface, which P@5 > 0.88 bounded. 2026-12-04, with the vote
  // saturation relative to the window (a quarter of it, 7.1 votes here; it was 10,
  // a third of this rod's 28-view window): clean P 0.990, thin R 0.901;
  // degraded P 0.862 (P@10 1.000), thin R 0.728 -- more of the rod kept, a
  // little thicker; P@5 > 0.84 bounds it (on a whole loop, the quality
  // table's thin-degraded set, P@5 is 1.000).
  EXPECT_GT(clean.precision, 0.95);
  EXPECT_GT(clean.thin_recall, 0.30);
  EXPECT_GT(degraded.precision_10mm, 0.95);
  EXPECT_GT(degraded.precision, 0.84);
  EXPECT_GT(degraded.thin_recall, 0.25);
}

}  // namespace
}  // namespace lfrecon
