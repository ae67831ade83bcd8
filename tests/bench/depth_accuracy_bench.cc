// Benchmark (not a test): sparse and filtered depth accuracy, coverage and
// time per view on a dataset with ground-truth depth (figurines or synthetic).
//   depth_accuracy_bench DATASET [--gt-views N] [--skip K] [--threads T] [--no-hierarchy] [--no-filter]
//                        [--every-view] [--shift-iterations N] [--voxel METRES] [--level-step DEG]
//                        [--level-ratio R] [--reference-points K] [--resample-reference]
// Evaluates the first N views that have ground truth (after skipping the
// first --skip ones), streaming frames from the start of the sequence.
// --every-view: depth (and filtering) of every view from the first to the
// last evaluated one, as the pipeline runs it (the vote window then moves by
// one view per filtered view); accuracy is still measured on the views with
// ground truth only.
// --level-step: GradientDepthOptions::level_min_step_deg (0: every view within 5°).
// --level-ratio: GradientDepthOptions::level_angle_ratio; --reference-points:
// GradientDepthOptions::refine_reference_points; --resample-reference:
// GradientDepthOptions::reuse_reference_patch off.
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>

#include <cstdio>
#include <cstring>
#include <string>

#include "depth/streaming_depth.h"
#include "eval/depth_metrics.h"
#include "io/dataset.h"
#include "io/depth_map_io.h"
#include "util/memory.h"
#include "util/progress.h"

using namespace lfrecon;

namespace {
void PrintCurve(const char* name, const DepthMetrics& m) {
  std::printf("%s: accuracy %.4f coverage %.4f\n", name, m.Accuracy(), m.Coverage());
  for (const CurvePoint& p : AccuracyCoverageCurve(m, 10))
    std::printf("  %s conf >= %.4f: accuracy %.4f coverage %.4f\n", name, p.min_confidence, p.accuracy, p.coverage);
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s DATASET [--gt-views N] [--skip K] [--threads T] [--no-hierarchy] [--no-filter] "
                 "[--every-view] [--shift-iterations N] [--voxel METRES] [--level-step DEG] [--level-ratio R] "
                 "[--reference-points K] [--resample-reference]\n",
                 argv[0]);
    return 2;
  }
  DatasetOptions dopt;
  dopt.dataset_dir = argv[1];
  int gt_views = 4, skip = 1, threads = 2;
  bool every_view = false;
  StreamingDepthOptions sopt;
  for (int a = 2; a < argc; ++a) {
    if (!std::strcmp(argv[a], "--gt-views") && a + 1 < argc) gt_views = std::atoi(argv[++a]);
    else if (!std::strcmp(argv[a], "--skip") && a + 1 < argc) skip = std::atoi(argv[++a]);
    else if (!std::strcmp(argv[a], "--threads") && a + 1 < argc) threads = std::atoi(argv[++a]);
    else if (!std::strcmp(argv[a], "--no-hierarchy")) sopt.gradient.use_hierarchy = false;
    else if (!std::strcmp(argv[a], "--resample-reference")) sopt.gradient.reuse_reference_patch = false;
    else if (!std::strcmp(argv[a], "--no-filter")) sopt.run_filter = false;
    else if (!std::strcmp(argv[a], "--every-view")) every_view = true;
    else if (!std::strcmp(argv[a], "--shift-iterations") && a + 1 < argc) sopt.gradient.shift_iterations = std::atoi(argv[++a]);
    else if (!std::strcmp(argv[a], "--voxel") && a + 1 < argc) sopt.filter.voxel_size = std::atof(argv[++a]);
    else if (!std::strcmp(argv[a], "--level-step") && a + 1 < argc) sopt.gradient.level_min_step_deg = std::atof(argv[++a]);
    else if (!std::strcmp(argv[a], "--level-ratio") && a + 1 < argc) sopt.gradient.level_angle_ratio = std::atof(argv[++a]);
    else if (!std::strcmp(argv[a], "--shift-tolerance") && a + 1 < argc)
      sopt.gradient.shift_tolerance_px = std::atof(argv[++a]);
    else if (!std::strcmp(argv[a], "--reference-points") && a + 1 < argc)
      sopt.gradient.refine_reference_points = std::atoi(argv[++a]);
    else {
      std::fprintf(stderr, "unknown or incomplete option %s\n", argv[a]);
      return 2;
    }
  }
  spdlog::set_level(spdlog::level::warn);
  tbb::global_control control(tbb::global_control::max_allowed_parallelism, threads);
  const Dataset ds = Dataset::Open(dopt);
  std::vector<int> wanted;
  int seen = 0;
  for (int i = 0; i < ds.NumViews() && static_cast<int>(wanted.size()) < gt_views; ++i)
    if (ds.GroundTruthDepthPath(i) && seen++ >= skip) wanted.push_back(i);
  if (every_view && !wanted.empty()) {
    const int first = wanted.front(), last = wanted.back();
    wanted.clear();
    for (int i = first; i <= last; ++i) wanted.push_back(i);
  }
  std::vector<PinholeView> views;
  for (int i = 0; i < ds.NumViews(); ++i) views.push_back(ds.View(i));
  auto frames = ds.OpenFrames();
  StreamingDepth stage(views, ds.bbox(), sopt);
  DepthMetrics sparse_total, filtered_total;
  cv::Mat last_image;
  Timer timer;
  const StreamingDepthStats stats = stage.Run(*frames, wanted, [&](int i, const cv::Mat& image, const DepthMap& sp, const DepthMap& fi) {
    if (!ds.GroundTruthDepthPath(i)) return;  // --every-view: timed, not evaluated
    const cv::Mat gt = ReadDepthMap(*ds.GroundTruthDepthPath(i));
    const DepthMetrics ms = EvaluateDepth(sp, gt, image, views[i], ds.bbox(), DepthMetricsOptions());
    sparse_total.Add(ms);
    std::printf("view %4d: sparse accuracy %.3f coverage %.3f", i, ms.Accuracy(), ms.Coverage());
    if (!fi.depth.empty()) {
      const DepthMetrics mf = EvaluateDepth(fi, gt, image, views[i], ds.bbox(), DepthMetricsOptions());
      filtered_total.Add(mf);
      std::printf(" | filtered accuracy %.3f coverage %.3f", mf.Accuracy(), mf.Coverage());
    }
    std::printf("\n");
    if (getenv("LFRECON_BENCH_HIST")) {
      // Relative error histogram of sparse foreground estimates, for diagnosis.
      int bins[6] = {0}, disc_bins[6] = {0};
      const double edges[5] = {0.005, 0.01, 0.02, 0.05, 0.2};
      for (int r = 0; r < gt.rows; ++r)
        for (int c = 0; c < gt.cols; ++c) {
          const float t = gt.at<float>(r, c), e = sp.depth.at<float>(r, c);
          if (!(t > 0) || !(e > 0)) continue;
          if (!ds.bbox().Contains(views[i].Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), t))) continue;
          const double rel = std::abs(e - t) / t;
          int b = 0;
          while (b < 5 && rel > edges[b]) ++b;
          bool disc = false;  // a depth discontinuity within 2 px
          for (int dr = -2; dr <= 2; ++dr)
            for (int dc = -2; dc <= 2; ++dc) {
              const int rr = std::clamp(r + dr, 0, gt.rows - 1), cc = std::clamp(c + dc, 0, gt.cols - 1);
              const float o = gt.at<float>(rr, cc);
              if (!(o > 0) || std::abs(o - t) > 0.02 * t) disc = true;
            }
          ++(disc ? disc_bins : bins)[b];
        }
      std::printf("  smooth:  rel err <0.5%% %d, <1%% %d, <2%% %d, <5%% %d, <20%% %d, more %d\n", bins[0], bins[1],
                  bins[2], bins[3], bins[4], bins[5]);
      std::printf("  near discontinuity: <0.5%% %d, <1%% %d, <2%% %d, <5%% %d, <20%% %d, more %d\n", disc_bins[0],
                  disc_bins[1], disc_bins[2], disc_bins[3], disc_bins[4], disc_bins[5]);
    }
    std::fflush(stdout);
  });
  const double total = timer.Seconds();
  std::printf("views %zu, frames read %d, sparse maps %d (%.0f ms each, %.1f neighbours each), filtered %d (%.0f ms each), "
              "max frames held %d, max sparse held %d, total %.1f s, peak RSS %.0f MiB, threads %d, level step %.2f deg\n",
              wanted.size(), stats.frames_read, stats.sparse_maps,
              1000 * stats.seconds_sparse / std::max(1, stats.sparse_maps),
              static_cast<double>(stats.neighbors_used) / std::max(1, stats.sparse_maps), stats.filtered_maps,
              1000 * stats.seconds_filter / std::max(1, stats.filtered_maps), stats.max_frames_held,
              stats.max_sparse_held, total, PeakRssBytes() / 1048576.0, threads, sopt.gradient.level_min_step_deg);
  PrintCurve("sparse", sparse_total);
  if (sopt.run_filter) PrintCurve("filtered", filtered_total);
  return 0;
}
