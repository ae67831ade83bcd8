// Fusion at scale: a long synthetic sequence streamed straight from the
// generator (nothing on disk), with time per stage and memory as it grows.
//
//   scale_bench [--mode exact|pipeline|maps] [--frames 3000] [--width 1280] [--height 720] [--scene tabletop]
//               [--loops L] [--voxel-divisions 256] [--budget-mib 1024] [--max-block 16]
//               [--report-every 250] [--threads N] [--eval] [--no-refine] [--mesh OUT.ply]
//               [--compare-exact] [--budgets-mib 0,64,16] [DATASET DEPTH_OUT]   (maps mode)
//
// --mode exact (default): renders each frame's exact depth and labels
//   (confidence 1, one sample per pixel, no image noise) and fuses it, as the
//   fusion tests do: fusion's own time and memory at full length and
//   resolution, without the per-view depth estimation (~8.6 s of CPU per 720p view).
// --mode pipeline: the whole `lfrecon run` (EmbeddedPipeline: depth from
//   gradients, filtering, densification, fusion, refinement) on rendered frames.
// --mode maps DATASET DEPTH_OUT: fuses depth maps written by `lfrecon run
//   --write-depth` (depth/<stem>.pfm, confidence/<stem>.pfm; foreground = inside V)
//   as the pipeline does (σ_s 0.15, activation from c >= 0.01) once per budget
//   of --budgets-mib (e.g. 0,64,16: 0 = exact) and scores each against the
//   dataset's ground truth: the cost of the store budget on real dense maps.
// --compare-exact (exact mode): also fuses every frame without a budget and
//   compares H voxel by voxel and the F-scores at the end (memory: the whole store).
// --budget-mib: FusionOptions::store_budget_bytes (0: unlimited); --loops: turns
//   of the camera over the N frames (0: the scene's default, one turn).
// --consistency V,RHO,R (pipeline mode): PropagationOptions::consistency views,
//   rho_min, patch_radius_px (V = 0: no check); --max-frame-gap N: StreamingDepthOptions::max_frame_gap;
//   --ray-margin M: GradientDepthOptions::ray_margin (negative: every edge pixel gets a depth);
//   --peak-fraction F: GradientDepthOptions::gradient_peak_fraction (1: only gradient maxima get a depth);
//   --photo-max-views N: PhotoconsistencyOptions::max_views of the densification (0: every view within 5°).
//   --rim-trim-rounds N, --smooth-iterations N: PipelineOptions::rim_trim.rounds and mesh_smoothing.iterations
//   of the final mesh (as `lfrecon run`'s flags; 0: off).
// --view-stride K (pipeline mode): PipelineOptions::views = 0, K, 2K, ... (`lfrecon run --views
//   0:N:K`): only those views get depth maps and are fused; every frame is still read and
//   serves as a neighbour (hierarchy, photoconsistency). At 3000 frames a loop (0.12°) K = 5
//   processes the views of the hierarchy grid (0.6° apart), whose sparse maps the filter
//   needs anyway.
// --8bit (pipeline mode): frames quantized to 8 bits as decoded PNG/video frames
//   are (the renderer's are float); --frames-dir DIR (pipeline mode): the frames
//   are first rendered to DIR/frame_NNNNN.png (8-bit, untimed; frames already
//   there are kept, DIR/scale_bench.txt names the sequence they belong to), then
//   the pipeline reads them back from the folder as `lfrecon run` does: the
//   product's time on a folder or decoded video, without the ~0.25 s per 720p
//   frame the renderer costs (the same 8-bit frames as --8bit); --no-compact: PipelineOptions::compact_frames
//   off (windows hold CV_32FC3 frames).
// Every --report-every frames it prints the cumulative seconds per stage, the
// fusion's grid and store sizes, and the current and peak RSS.
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>

#include <cstdio>
#include <algorithm>
#include <cstdlib>
#include <memory>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "eval/mesh_metrics.h"
#include "fusion/probabilistic_fusion.h"
#include "io/dataset.h"
#include "io/depth_map_io.h"
#include "io/ply.h"
#include "pipeline/embedded_pipeline.h"
#include "synth/renderer.h"
#include "synth/sequence.h"
#include "util/memory.h"
#include "util/progress.h"

using namespace lfrecon;

namespace {

double MiB(double bytes) { return bytes / 1048576.0; }

// --mode maps: one fusion per budget over maps on disk.
int RunMaps(const std::string& dataset_dir, const std::string& depth_dir, const std::vector<double>& budgets_mib,
            int max_block) {
  namespace fs = std::filesystem;
  DatasetOptions dopt;
  dopt.dataset_dir = dataset_dir;
  const Dataset ds = Dataset::Open(dopt);
  const auto gt_path = ds.GroundTruthMeshPath(false);
  const auto thin_path = ds.GroundTruthMeshPath(true);
  if (!gt_path) {
    std::fprintf(stderr, "%s has no ground-truth mesh\n", dataset_dir.c_str());
    return 1;
  }
  const TriangleMesh gt = ReadPly(*gt_path);
  TriangleMesh thin;
  if (thin_path) thin = ReadPly(*thin_path);
  std::vector<int> ids;
  std::vector<DepthMap> maps;
  for (int i = 0; i < ds.NumViews(); ++i) {
    const std::string stem = fs::path(ds.views()[i].name).stem().string();
    const fs::path d = fs::path(depth_dir) / "depth" / (stem + ".pfm");
    const fs::path c = fs::path(depth_dir) / "confidence" / (stem + ".pfm");
    if (!fs::exists(d)) continue;
    DepthMap m;
    m.depth = ReadPfm(d);
    if (fs::exists(c)) m.confidence = ReadPfm(c);
    ids.push_back(i);
    maps.push_back(std::move(m));
  }
  const PipelineOptions po;
  const double voxel = PipelineVoxelSize(ds.bbox(), po);
  std::printf("%zu maps from %s, voxel %.2f mm, sigma_s %.2f, activation from c >= %.2f\n", maps.size(),
              depth_dir.c_str(), voxel * 1000, po.dense_sigma_s, po.fusion.activation_min_confidence);
  std::printf("%10s %9s %6s %8s %7s %7s %7s %7s %7s %7s %9s %9s %9s %8s %8s\n", "budget_MiB", "store_MiB", "block",
              "coarse", "F@2", "F@5", "F@10", "P@5", "R@5", "thin@5", "active", "flipped", "mean|dH|", "fuse_s",
              "backfill");
  std::unique_ptr<ProbabilisticFusion> exact;
  for (double b : budgets_mib) {
    FusionOptions fo = po.fusion;
    fo.volume = ds.bbox();
    fo.voxel_size = voxel;
    fo.sigma_s = po.dense_sigma_s;
    fo.store_budget_bytes = static_cast<std::size_t>(b * 1048576.0);
    fo.store_max_block = max_block;
    auto fusion = std::make_unique<ProbabilisticFusion>(fo);
    Timer t;
    for (std::size_t k = 0; k < maps.size(); ++k) fusion->Integrate(ds.View(ids[k]), maps[k], ids[k]);
    const double fuse_s = t.Seconds();
    const TriangleMesh mesh = fusion->ExtractMesh();
    MeshMetricsOptions mo;
    mo.volume = ds.bbox();
    const MeshMetrics m = EvaluateMesh(mesh, gt, thin_path ? &thin : nullptr, mo);
    // H against the first (normally exact, budget 0) run.
    std::size_t flipped = 0, n = 0;
    double mean = 0;
    if (exact) {
      exact->ForEachVoxel([&](const Eigen::Vector3i& v, double sum, int views) {
        const double he = views > 0 ? std::exp(sum / views) : 0.0, hb = fusion->SurfaceProbability(v);
        flipped += (he >= fo.surface_threshold) != (hb >= fo.surface_threshold);
        mean += std::abs(he - hb);
        ++n;
      });
    }
    const FusionStats s = fusion->Stats();
    std::printf("%10.0f %9.1f %6d %8d %7.4f %7.4f %7.4f %7.4f %7.4f %7.4f %9zu %9zu %9.5f %8.1f %8.1f\n", b,
                MiB(s.store_bytes), s.store_max_block, s.store_coarsened_views, m.scores[0].fscore,
                m.scores[1].fscore, m.scores[2].fscore, m.scores[1].precision, m.scores[1].recall,
                m.scores[1].thin_recall, s.active_voxels, flipped, n > 0 ? mean / n : 0.0, fuse_s, s.backfill_s);
    std::fflush(stdout);
    if (!exact) exact = std::move(fusion);
  }
  std::printf("peak RSS %.0f MiB\n", MiB(PeakRssBytes()));
  return 0;
}

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

namespace lfrecon {
namespace {
// Frames of `inner` quantized to 8 bits, as an 8-bit PNG or video frame decodes.
class EightBitSource : public FrameSource {
 public:
  explicit EightBitSource(FrameSource* inner) : inner_(inner) {}
  int NumFrames() const override { return inner_->NumFrames(); }
  bool Next(Frame* frame) override {
    if (!inner_->Next(frame)) return false;
    Quantize(frame);
    return true;
  }
  Frame Read(int index) override {
    Frame f = inner_->Read(index);
    Quantize(&f);
    return f;
  }

 private:
  static void Quantize(Frame* f) {
    cv::Mat u8;
    f->image.convertTo(u8, CV_8U, 255.0);
    f->image = ToFloatBgr(u8);
  }
  FrameSource* inner_;
};

std::string SequenceStamp(const std::string& scene, int frames, int width, int height, double loops) {
  char buf[256];
  std::snprintf(buf, sizeof buf, "scene %s, frames %d, %dx%d, loops %.6g\n", scene.c_str(), frames, width, height,
                loops);
  return buf;
}

// Renders every frame of `source` that `dir` lacks to dir/frame_NNNNN.png (8
// bits) and returns a source reading them back. Refuses a folder whose stamp
// names another sequence, so a stale folder is never measured by mistake.
std::unique_ptr<ImageFolderSource> RenderToFolder(FrameSource* source, const std::filesystem::path& dir,
                                                  const std::string& stamp) {
  namespace fs = std::filesystem;
  fs::create_directories(dir);
  const fs::path stamp_path = dir / "scale_bench.txt";
  if (fs::exists(stamp_path)) {
    std::ifstream in(stamp_path);
    const std::string old((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (old != stamp) {
      std::fprintf(stderr, "%s holds frames of another sequence (%s); use another --frames-dir\n",
                   dir.string().c_str(), old.c_str());
      std::exit(2);
    }
  } else {
    std::ofstream(stamp_path) << stamp;
  }
  const int n = source->NumFrames();
  std::vector<std::string> names;
  Timer t;
  int rendered = 0;
  for (int i = 0; i < n; ++i) {
    char name[32];
    std::snprintf(name, sizeof name, "frame_%05d.png", i);
    names.push_back(name);
    if (fs::exists(dir / name)) continue;
    const fs::path tmp = dir / (std::string(name) + ".tmp.png");  // a cut-off run leaves no half-written frame
    WriteImageFloat(tmp, source->Read(i).image);
    fs::rename(tmp, dir / name);
    if (++rendered % 250 == 0) {
      std::printf("rendered %d frames to %s, %.1f s\n", rendered, dir.string().c_str(), t.Seconds());
      std::fflush(stdout);
    }
  }
  std::printf("frames: %d in %s (%d rendered now, %.1f s, untimed)\n", n, dir.string().c_str(), rendered,
              t.Seconds());
  std::fflush(stdout);
  return std::make_unique<ImageFolderSource>(dir, std::move(names));
}
}  // namespace
}  // namespace lfrecon

int main(int argc, char** argv) {
  lfrecon::ConfigureHeap();
  std::string mode = "exact", scene = "tabletop", mesh_out, frames_dir;
  DenseConsistencyOptions consistency;
  int max_frame_gap = StreamingDepthOptions{}.max_frame_gap;
  std::optional<double> ray_margin, peak_fraction;
  std::optional<int> photo_max_views;
  std::optional<int> rim_trim_rounds, smooth_iterations;
  int frames = 3000, width = 1280, height = 720, divisions = 256, report_every = 250, threads = 0, max_block = 16;
  int view_stride = 1;
  double loops = 0, budget_mib = 1024;
  bool eval = false, refine = true, compare = false, eight_bit = false, compact = true;
  std::vector<double> budgets = {0, 64, 16};
  std::vector<std::string> positional;
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
    else if (k == "--8bit") eight_bit = true;
    else if (k == "--frames-dir") frames_dir = value();
    else if (k == "--consistency") {  // views,rho_min,patch_radius_px of the dense check (views 0: off)
      std::sscanf(value().c_str(), "%d,%lf,%d", &consistency.views, &consistency.rho_min,
                  &consistency.patch_radius_px);
    } else if (k == "--ray-margin") ray_margin = std::atof(value().c_str());  // negative: every edge pixel
    else if (k == "--peak-fraction") peak_fraction = std::atof(value().c_str());
    else if (k == "--photo-max-views") photo_max_views = std::atoi(value().c_str());
    else if (k == "--rim-trim-rounds") rim_trim_rounds = std::atoi(value().c_str());
    else if (k == "--smooth-iterations") smooth_iterations = std::atoi(value().c_str());
    else if (k == "--max-frame-gap") max_frame_gap = std::atoi(value().c_str());
    else if (k == "--no-compact") compact = false;
    else if (k == "--view-stride") view_stride = std::atoi(value().c_str());
    else if (k == "--compare-exact") compare = true;
    else if (k == "--budgets-mib") {
      budgets.clear();
      std::stringstream ss(value());
      std::string item;
      while (std::getline(ss, item, ',')) budgets.push_back(std::atof(item.c_str()));
    } else if (k.rfind("--", 0) != 0) positional.push_back(k);
    else {
      std::fprintf(stderr, "unknown option %s (see the header of scale_bench.cc)\n", k.c_str());
      return 2;
    }
  }
  if (mode == "maps") {
    if (positional.size() != 2) {
      std::fprintf(stderr, "--mode maps needs DATASET DEPTH_OUT\n");
      return 2;
    }
    spdlog::set_level(spdlog::level::warn);
    std::optional<tbb::global_control> control;
    if (threads > 0) control.emplace(tbb::global_control::max_allowed_parallelism, threads);
    return RunMaps(positional[0], positional[1], budgets, max_block);
  }
  if ((mode != "exact" && mode != "pipeline") || frames < 1 || report_every < 1 || view_stride < 1) {
    std::fprintf(stderr, "bad --mode / --frames / --report-every / --view-stride\n");
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
    std::unique_ptr<ProbabilisticFusion> exact;
    if (compare) {
      FusionOptions unlimited = fo;
      unlimited.store_budget_bytes = 0;
      exact = std::make_unique<ProbabilisticFusion>(unlimited);
    }
    double render_s = 0, fuse_s = 0, exact_s = 0;
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
      if (exact) {
        t.Restart();
        exact->Integrate(view, d, i);
        exact_s += t.Seconds();
      }
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
    if (exact) {
      std::size_t flipped = 0, n = 0, missing = 0;
      double mean = 0, max = 0;
      exact->ForEachVoxel([&](const Eigen::Vector3i& v, double sum, int views) {
        const double he = views > 0 ? std::exp(sum / views) : 0.0, hb = fusion.SurfaceProbability(v);
        flipped += (he >= fo.surface_threshold) != (hb >= fo.surface_threshold);
        missing += !fusion.IsActive(v);
        mean += std::abs(he - hb);
        max = std::max(max, std::abs(he - hb));
        ++n;
      });
      std::printf("exact (no budget): fusion %.1f s, store %.1f MiB; against it, with the budget: %zu voxels, %zu "
                  "missing, max |dH| %.4f, mean |dH| %.6f, %zu flipped at H = %.2f\n",
                  exact_s, MiB(exact->Stats().store_bytes), n, missing, max, n > 0 ? mean / n : 0.0, flipped,
                  fo.surface_threshold);
      if (eval) PrintScores("fused, exact store", exact->ExtractMesh(), *seq);
    }
    return 0;
  }

  // The whole pipeline.
  std::vector<PinholeView> views;
  for (int i = 0; i < frames; ++i) views.push_back(seq->View(i));
  PipelineOptions po;
  po.voxel_divisions = divisions;
  po.refine = refine;
  po.compact_frames = compact;
  po.propagation.consistency = consistency;
  po.depth.max_frame_gap = max_frame_gap;
  if (ray_margin) po.depth.gradient.ray_margin = *ray_margin;
  if (peak_fraction) po.depth.gradient.gradient_peak_fraction = *peak_fraction;
  if (photo_max_views) po.propagation.photo.max_views = *photo_max_views;
  if (rim_trim_rounds) po.rim_trim.rounds = *rim_trim_rounds;
  if (smooth_iterations) po.mesh_smoothing.iterations = *smooth_iterations;
  po.write_vdb = false;
  po.write_turntable = false;
  po.fusion.store_budget_bytes = budget;
  po.fusion.store_max_block = max_block;
  if (view_stride > 1)
    for (int i = 0; i < frames; i += view_stride) po.views.push_back(i);
  EmbeddedPipeline pipeline(views, volume, po);
  pipeline.SetViewCallback([&](int, int done, int n) {
    if (done % report_every == 0 || done == n) {
      std::printf("%d of %d views fused, %.1f s, RSS %.0f MiB, peak %.0f MiB\n", done, n, total.Seconds(),
                  MiB(CurrentRssBytes()), MiB(PeakRssBytes()));
      std::fflush(stdout);
    }
  });
  synth::SynthFrameSource synth_source(seq);
  EightBitSource eight_bit_source(&synth_source);
  std::unique_ptr<ImageFolderSource> folder_source;
  if (!frames_dir.empty()) {
    folder_source = RenderToFolder(&synth_source, frames_dir, SequenceStamp(scene, frames, width, height, loops));
    total = Timer();  // the rendering is not the pipeline's time
  }
  FrameSource& source = folder_source ? static_cast<FrameSource&>(*folder_source)
                        : eight_bit   ? static_cast<FrameSource&>(eight_bit_source)
                                      : synth_source;
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
              "densify %d, pending in the depth stage %d\n",
              MiB(st.peak_rss_bytes), MiB(st.grid_bytes), st.active_voxels,
              MiB(r.report["counts"]["depth_store_bytes"].get<double>()), st.max_frames_held_depth,
              st.max_frames_held_pipeline, st.max_frames_pending_depth);
  std::fflush(stdout);
  {
    double sum = 0;  // identity check between runs
    for (const auto& v : r.mesh_raw.vertices) sum += v.x() + 2 * v.y() + 3 * v.z();
    std::printf("result: fused pixels %lld, active voxels %zu, mesh_raw %zu vertices, vertex checksum %.17g\n",
                st.fused_pixels, st.active_voxels, r.mesh_raw.vertices.size(), sum);
  }
  if (!mesh_out.empty()) WritePly(r.mesh_raw, mesh_out);
  if (eval) {
    PrintScores("fused (mesh_raw)", r.mesh_raw, *seq);
    if (refine) PrintScores("refined (mesh)", r.mesh, *seq);
  }
  return 0;
}
