// A generated scene with object masks and no scene.json: V comes from the
// masks (their visual hull, Dataset::Open) and the mesh is at least as good as
// the one from the same frames and masks with scene.json's V (issue 17). Same
// loop as degraded_capture_test's clean twin (72 frames of 192x108 over a
// quarter loop), written to disk as `lfrecon synth --masks` writes it and read
// back through Dataset as `lfrecon run` reads a folder.
#include <gtest/gtest.h>

#include <cstdio>
#include <filesystem>

#include "common/test_util.h"
#include "eval/mesh_metrics.h"
#include "io/dataset.h"
#include "pipeline/embedded_pipeline.h"
#include "pipeline/quarter_loop.h"
#include "synth/sequence.h"
#include "synth/writer.h"

namespace lfrecon {
namespace {

namespace fs = std::filesystem;

struct Outcome {
  BoundingBox volume;
  std::string volume_source;
  double f5 = 0, precision = 0, recall = 0;
};

// lfrecon run's path for a folder: the dataset's views, V and masks (free
// space in fusion, the default), then the mesh scored against the truth.
Outcome Reconstruct(const fs::path& dir, const synth::SynthSequence& seq) {
  DatasetOptions d;
  d.dataset_dir = dir;
  const Dataset ds = Dataset::Open(d);
  EXPECT_TRUE(ds.HasMasks());
  std::vector<PinholeView> views;
  for (int i = 0; i < ds.NumViews(); ++i) views.push_back(ds.View(i));
  PipelineOptions options;
  options.color_views = 0;
  EmbeddedPipeline pipeline(views, ds.bbox(), options);
  pipeline.SetMasks([&ds](int i) { return ds.ReadMask(i); });
  auto frames = ds.OpenFrames();
  const PipelineResult r = pipeline.Run(*frames);
  MeshMetricsOptions mo;
  mo.thresholds = {0.005};
  mo.volume = seq.scene().foreground_bbox();  // the same scoring box for both
  const MeshMetrics m = EvaluateMesh(r.mesh, seq.GroundTruthMesh(), nullptr, mo);
  return {ds.bbox(), ds.bbox_source(), m.scores[0].fscore, m.scores[0].precision, m.scores[0].recall};
}

TEST(MasksVolume, MeshFromTheMasksVolumeIsAtLeastAsGoodAsFromSceneJson) {
  synth::SynthOptions o = testing::TabletopQuarterLoop();
  o.render.noise_sigma = 0.005;
  const synth::SynthSequence seq = synth::SynthSequence::Create(o);
  testing::TempDir tmp;
  synth::SynthWriteOptions w;
  w.out_dir = tmp.path() / "with_scene_json";
  w.depth_every = 0;
  w.write_meshes = false;
  w.write_masks = true;
  synth::WriteSynthDataset(seq, w);
  fs::copy(w.out_dir, tmp.path() / "masks_only", fs::copy_options::recursive);
  fs::remove(tmp.path() / "masks_only" / "scene.json");

  const Outcome given = Reconstruct(w.out_dir, seq);
  const Outcome masks = Reconstruct(tmp.path() / "masks_only", seq);
  EXPECT_EQ(given.volume_source, "scene.json");
  EXPECT_EQ(masks.volume_source.rfind("masks", 0), 0u) << masks.volume_source;
  const auto size = [](const BoundingBox& b) { return b.max - b.min; };
  std::printf("V from scene.json %.3f x %.3f x %.3f m, from the masks %.3f x %.3f x %.3f m; F@5mm (P/R): %.3f "
              "(%.3f/%.3f) with scene.json's V, %.3f (%.3f/%.3f) with the masks'\n",
              size(given.volume).x(), size(given.volume).y(), size(given.volume).z(), size(masks.volume).x(),
              size(masks.volume).y(), size(masks.volume).z(), given.f5, given.precision, given.recall, masks.f5,
              masks.precision, masks.recall);
  // Measured (2026-12-05): V 0.520 x 0.520 x 0.415 m from scene.json, 0.475 x 0.449 x 0.377 m
  // from the masks (its bottom 0.11 m under the table plane, its top at 0.268 m against 0.420);
  // F@5mm 0.561 (P 0.624, R 0.509) with scene.json's V, 0.570 (0.593, 0.548) with the masks'.
  EXPECT_GT(given.f5, 0.4);
  // "At least as good": no worse than scene.json's V beyond the run-to-run noise of a few meshes' samples.
  EXPECT_GE(masks.f5, given.f5 - 0.01);
}

}  // namespace
}  // namespace lfrecon
