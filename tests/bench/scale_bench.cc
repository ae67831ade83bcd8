// Fusion at scale: a long synthetic sequence streamed straight from the
// generator (nothing on disk), with time per stage and memory as it grows.
//
//   scale_bench [--mode exact|pipeline] [--frames 3000] [--width 1280] [--height 720] [--scene tabletop]
//               [--loops L] [--voxel-divisions 256] [--budget-mib 1024] [--max-block 16]
//               [--report-every 250] [--threads N] [--eval] [--no-refine] [--mesh OUT.ply]
//
// --mode exact (default): renders each frame's exact depth and labels
//   (confidence 1, one sample per pixel, no image noise) and fuses it, as the
//   fusion tests do: fusion's own time and memory at full length and
//   resolution, without the per-view depth estimation (~8.6 s of CPU per 720p view).
// --mode pipeline: the whole `lfrecon run` (EmbeddedPipeline: depth from
//   gradients, filtering, densification, fusion, refinement) on rendered frames.
// --budget-mib: FusionOptions::store_budget_bytes (0: unlimited); --loops: turns
//   of the camera over the N frames (0: the scene's default, one turn).
// Every --report-every frames it prints the cumulative seconds per stage, the
// fusion's grid and store sizes, and the current and peak RSS.
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>

#include <cstdio>
#include <cstdlib>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "eval/mesh_metrics.h"
#include "fusion/probabilistic_fusion.h"
#include "io/ply.h"
#include "pipeline/embedded_pipeline.h"
#include "synth/renderer.h"
#include "synth/sequence.h"
#include "util/memory.h"
#include "util/progress.h"

using namespace lfrecon;

namespace {

double MiB(double bytes) { return bytes / 1048576.0; }

void PrintScores(const char* what, const TriangleMesh& mesh, const synth::SynthSequence& seq) {
  Timer t;
  const TriangleMesh gt = seq.GroundTruthMesh(false), thin = seq.GroundTruthMesh(true);
  MeshMetricsOptions mo;
  mo.volume = seq.scene().foreground_bbox();
  const MeshMetrics m = EvaluateMesh(mesh, gt, thin.triangles.empty() ? nullptr : &thin, mo);
  for (const ThresholdScore& s : m.scores)
    std::printf("%s: tau %.0f mm  P %.4f  R %.4f  F %.4f  thin recall %.4f\n", what, s.threshold * 1000, s.precision,
                s.recall, s.fscore, s.thin_recall);
  std::printf("(evaluation %.1f s)\n", t.Seconds());
}

}  // namespace

int main(int argc, char** argv) {
  std::string mode = "exact", scene = "tabletop", mesh_out;
  int frames = 3000, width = 1280, height = 720, divisions = 256, report_every = 250, threads = 0, max_block = 16;
  double loops = 0, budget_mib = 1024;
  bool eval = false, refine = true;
  for (int a = 1; a < argc; ++a) {
    const std::string k = argv[a];
    auto value = [&]() -> std::string {
      if (a + 1 >= argc) {
        std::fprintf(stderr, "%s needs a value\n", k.c_str());
        std::exit(2);
      }
      return argv[++a];
    };
    if (k == "--mode") mode = value();
    else if (k == "--scene") scene = value();
    else if (k == "--frames") frames = std::atoi(value().c_str());
    else if (k == "--width") width = std::atoi(value().c_str());
    else if (k == "--height") height = std::atoi(value().c_str());
    else if (k == "--loops") loops = std::atof(value().c_str());
    else if (k == "--voxel-divisions") divisions = std::atoi(value().c_str());
    else if (k == "--budget-mib") budget_mib = std::atof(value().c_str());
    else if (k == "--max-block") max_block = std::atoi(value().c_str());
    else if (k == "--report-every") report_every = std::atoi(value().c_str());
    else if (k == "--threads") threads = std::atoi(value().c_str());
    else if (k == "--mesh") mesh_out = value();
    else if (k == "--eval") eval = true;
    else if (k == "--no-refine") refine = false;
    else {
      std::fprintf(stderr, "unknown option %s (see the header of scale_bench.cc)\n", k.c_str());
      return 2;
    }
  }
  if ((mode != "exact" && mode != "pipeline") || frames < 1 || report_every < 1) {
    std::fprintf(stderr, "bad --mode / --frames / --report-every\n");
    return 2;
  }
  std::optional<tbb::global_control> control;
  if (threads > 0) control.emplace(tbb::global_control::max_allowed_parallelism, threads);
  spdlog::set_level(spdlog::level::warn);

  synth::SynthOptions so;
  so.scene = scene;
  so.frames = frames;
  so.width = width;
  so.height = height;
  so.loops = loops;
  if (mode == "exact") {
    so.render.supersampling = 1;
    so.render.noise_sigma = 0;
  }
  auto seq = std::make_shared<const synth::SynthSequence>(synth::SynthSequence::Create(so));
  const BoundingBox volume = seq->scene().foreground_bbox();
  const double voxel = volume.Extent().maxCoeff() / divisions;
  const std::size_t budget = static_cast<std::size_t>(budget_mib * 1048576.0);
  std::printf("scale_bench: mode %s, %s, %d frames %dx%d, %.3f deg between frames, voxel %.2f mm, store budget %s\n",
              mode.c_str(), scene.c_str(), frames, width, height, seq->path().StepDeg(), voxel * 1000,
              budget == 0 ? "unlimited" : (std::to_string(static_cast<long long>(budget_mib)) + " MiB").c_str());
  std::printf("start: RSS %.0f MiB\n", MiB(CurrentRssBytes()));
  std::fflush(stdout);
  Timer total;

  if (mode == "exact") {
    FusionOptions fo;
    fo.volume = volume;
    fo.voxel_size = voxel;
    fo.store_budget_bytes = budget;
    fo.store_max_block = max_block;
    ProbabilisticFusion fusion(fo);
    double render_s = 0, fuse_s = 0;
    std::printf("%6s %8s %9s %9s %9s %9s %9s %9s %10s %8s %8s %6s %8s %8s\n", "frames", "wall_s", "render_s",
                "fusion_s", "activate", "backfill", "update", "coarsen", "active", "grid_MiB", "store_MiB", "block",
                "rss_MiB", "peak_MiB");
    for (int i = 0; i < frames; ++i) {
      Timer t;
      const PinholeView view = seq->View(i);
      const synth::RenderResult rr = synth::Render(seq->scene(), view, so.render, seq->FrameSeed(i));
      DepthMap d(view.height, view.width);
      rr.depth.convertTo(d.depth, CV_32F);
      const cv::Mat fg = synth::ForegroundMask(seq->scene(), rr.labels);
      d.confidence.setTo(0.0f);
      d.confidence.setTo(1.0f, d.depth > 0);
      d.label.setTo(static_cast<int>(DepthLabel::kBackground));
      d.label.setTo(static_cast<int>(DepthLabel::kForeground), fg);
      render_s += t.Seconds();
      t.Restart();
      fusion.Integrate(view, d, i);
      fuse_s += t.Seconds();
      if ((i + 1) % report_every == 0 || i + 1 == frames) {
        const FusionStats s = fusion.Stats();
        std::printf("%6d %8.1f %9.1f %9.1f %9.1f %9.1f %9.1f %9.1f %10zu %8.1f %9.1f %6d %8.0f %8.0f\n", i + 1,
                    total.Seconds(), render_s, fuse_s, s.activate_s, s.backfill_s, s.update_s, s.coarsen_s,
                    s.active_voxels, MiB(s.grid_bytes), MiB(s.store_bytes), s.store_max_block,
                    MiB(CurrentRssBytes()), MiB(PeakRssBytes()));
        std::fflush(stdout);
      }
    }
    Timer tm;
    const TriangleMesh mesh = fusion.ExtractMesh();
    const double mesh_s = tm.Seconds();
    const FusionStats s = fusion.Stats();
    std::printf("done: %d frames in %.1f s: render %.1f s (%.3f s/frame), fusion %.1f s (%.3f s/frame: activate "
                "%.3f, back-fill %.3f, update %.3f, coarsen %.3f), mesh %.1f s (%zu triangles)\n",
                frames, total.Seconds(), render_s, render_s / frames, fuse_s, fuse_s / frames, s.activate_s / frames,
                s.backfill_s / frames, s.update_s / frames, s.coarsen_s / frames, mesh_s, mesh.triangles.size());
    std::printf("memory: peak RSS %.0f MiB, grid %.1f MiB (%zu active voxels), store %.1f MiB (%d views coarsened, "
                "blocks up to %d)\n",
                MiB(PeakRssBytes()), MiB(s.grid_bytes), s.active_voxels, MiB(s.store_bytes), s.store_coarsened_views,
                s.store_max_block);
    std::fflush(stdout);
    if (!mesh_out.empty()) WritePly(mesh, mesh_out);
    if (eval) PrintScores("fused", mesh, *seq);
    return 0;
  }

  // The whole pipeline.
  std::vector<PinholeView> views;
  for (int i = 0; i < frames; ++i) views.push_back(seq->View(i));
  PipelineOptions po;
  po.voxel_divisions = divisions;
  po.refine = refine;
  po.write_vdb = false;
  po.write_turntable = false;
  po.fusion.store_budget_bytes = budget;
  po.fusion.store_max_block = max_block;
  EmbeddedPipeline pipeline(views, volume, po);
  pipeline.SetViewCallback([&](int, int done, int n) {
    if (done % report_every == 0 || done == n) {
      std::printf("%d of %d views fused, %.1f s, RSS %.0f MiB, peak %.0f MiB\n", done, n, total.Seconds(),
                  MiB(CurrentRssBytes()), MiB(PeakRssBytes()));
      std::fflush(stdout);
    }
  });
  synth::SynthFrameSource source(seq);
  const PipelineResult r = pipeline.Run(source);
  const PipelineStats& st = r.stats;
  const double n = st.views;
  std::printf("done: %d views in %.1f s (%.2f s/view)\n", st.views, st.seconds_total, st.seconds_total / n);
  std::printf("per view: sparse %.2f s, filter %.2f s, densify %.2f s, fusion %.3f s; once: mesh %.1f s, refine %.1f "
              "s, colour %.1f s\n",
              st.seconds_sparse / n, st.seconds_filter / n, st.seconds_densify / n, st.seconds_fusion / n,
              st.seconds_mesh, st.seconds_refine, st.seconds_color);
  std::printf("fusion split (s): activate %.1f, back-fill %.1f, update %.1f\n",
              r.report["seconds"]["fusion_activate"].get<double>(),
              r.report["seconds"]["fusion_backfill"].get<double>(), r.report["seconds"]["fusion_update"].get<double>());
  std::printf("memory: peak RSS %.0f MiB, grid %.1f MiB (%zu active voxels), store %.1f MiB; frames held: depth %d, "
              "densify %d\n",
              MiB(st.peak_rss_bytes), MiB(st.grid_bytes), st.active_voxels,
              MiB(r.report["counts"]["depth_store_bytes"].get<double>()), st.max_frames_held_depth,
              st.max_frames_held_pipeline);
  std::fflush(stdout);
  if (!mesh_out.empty()) WritePly(r.mesh_raw, mesh_out);
  if (eval) {
    PrintScores("fused (mesh_raw)", r.mesh_raw, *seq);
    if (refine) PrintScores("refined (mesh)", r.mesh, *seq);
  }
  return 0;
}
