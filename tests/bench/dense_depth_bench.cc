// Benchmark (not a test): dense depth (§4, bidirectional photoconsistency and
// edge-aware propagation) on a dataset with ground-truth depth (figurines or
// synthetic): accuracy and coverage over all ground-truth foreground pixels,
// and time per view with where it goes.
//   dense_depth_bench DATASET [--gt-views N] [--skip K] [--stride S] [--threads T] [--preview-dir DIR] [--cache DIR]
//                     [--sigma-spatial F] [--sigma-color C] [--guide-sigma S] [--mode nc|ic|rf|own]
//                     [--iterations N] [--min-confidence C] [--presmooth S] [--max-views N] [--[no-]centre-consistency] [--model constant|affine]
//                     [--ridge PX] [--extrapolation-m0 M] [--extrapolation-floor PX] [--paper] [--no-depth-confidence] [--no-keep-edge-depths]
//                     [--no-inverse-depth] [--two-sided] [--no-silhouette-splat-only] [--no-keep-blocked-silhouettes] [--oracle-depth]
//                     [--upscale F] [--repeat R] [--refine-views N] [--refine-steps N] [--refine-step-px P]
//                     [--refine-radius R] [--refine-ncc-min Z] [--refine-fronto-parallel]
// Options apply in order: --paper resets to PaperPropagationOptions(), later flags change it.
// --upscale F scales frames (bicubic), the filtered maps and ground truth
// (nearest) and the cameras by F, to time propagation at F× the resolution.
// --oracle-depth replaces the filtered depths by the true depth at the same
// pixels (diagnosis: what propagation alone loses). LFRECON_BENCH_DIAG=1 adds a
// breakdown by distance to the nearest depth and error maps in --preview-dir.
// The sparse and filtered maps come from StreamingDepth exactly as in
// depth_accuracy_bench; each wanted view is then densified with its
// neighbours within 5° (read by random access from a second frame source).
// Only DensifyDepth is timed (--repeat runs it R times and keeps the fastest).
// --stride S takes every S-th view with ground truth; --cache DIR stores the
// filtered maps (and reuses them when all are there) so that propagation
// settings can be compared without recomputing the depth stage.
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>

#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "depth/streaming_depth.h"
#include "eval/depth_metrics.h"
#include "geometry/view_graph.h"
#include "io/dataset.h"
#include "io/depth_map_io.h"
#include "propagation/dense_consistency.h"
#include "propagation/depth_propagator.h"
#include "propagation/edge_preview.h"
#include "util/memory.h"
#include "util/progress.h"

using namespace lfrecon;
namespace fs = std::filesystem;

namespace {
void PrintCurve(const char* name, const DepthMetrics& m) {
  std::printf("%s: accuracy %.4f coverage %.4f\n", name, m.Accuracy(), m.Coverage());
  for (const CurvePoint& p : AccuracyCoverageCurve(m, 10))
    std::printf("  %s conf >= %.4g: accuracy %.4f coverage %.4f\n", name, p.min_confidence, p.accuracy, p.coverage);
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr,
                 "usage: %s DATASET [--gt-views N] [--skip K] [--stride S] [--threads T] [--preview-dir DIR] [--cache DIR]\n"
                 "       [--sigma-spatial F] [--sigma-color C] [--guide-sigma S] [--mode nc|ic|rf|own] [--iterations N]\n"
                 "       [--min-confidence C] [--presmooth S] [--max-views N] [--model constant|affine] [--ridge PX]\n"
                 "       [--extrapolation-m0 M] [--extrapolation-floor PX]\n"
                 "       [--paper] [--no-depth-confidence] [--no-keep-edge-depths] [--no-inverse-depth] [--two-sided]\n"
                 "       [--no-silhouette-splat-only] [--no-keep-blocked-silhouettes] [--oracle-depth] [--upscale F] [--repeat R]\n",
                 argv[0]);
    return 2;
  }
  DatasetOptions dopt;
  dopt.dataset_dir = argv[1];
  int gt_views = 4, skip = 1, stride = 1, threads = 2, repeat = 1;
  bool oracle = false;
  // ρ of DenseConsistencyAccumulator by truth class (4 views; meaningful with --consistency-views 0).
  bool consistency_stats = false;
  int upscale = 1;
  std::string preview_dir, cache_dir;
  StreamingDepthOptions sopt;
  PropagationOptions popt;
  for (int a = 2; a < argc; ++a) {
    const auto is = [&](const char* name) { return !std::strcmp(argv[a], name) && a + 1 < argc; };
    if (is("--gt-views")) gt_views = std::atoi(argv[++a]);
    else if (is("--skip")) skip = std::atoi(argv[++a]);
    else if (is("--stride")) stride = std::max(1, std::atoi(argv[++a]));
    else if (is("--cache")) cache_dir = argv[++a];
    else if (is("--threads")) threads = std::atoi(argv[++a]);
    else if (is("--repeat")) repeat = std::max(1, std::atoi(argv[++a]));
    else if (is("--preview-dir")) preview_dir = argv[++a];
    else if (is("--sigma-spatial")) popt.dt_sigma_spatial = std::atof(argv[++a]);
    else if (is("--sigma-color")) popt.dt_sigma_color = std::atof(argv[++a]);
    else if (is("--guide-sigma")) popt.guide_sigma = std::atof(argv[++a]);
    else if (is("--iterations")) popt.dt_iterations = std::atoi(argv[++a]);
    else if (is("--min-confidence")) popt.min_filtered_confidence = std::atof(argv[++a]);
    else if (is("--upscale")) upscale = std::max(1, std::atoi(argv[++a]));
    else if (is("--max-views")) popt.photo.max_views = std::atoi(argv[++a]);
    else if (!std::strcmp(argv[a], "--centre-consistency")) popt.photo.centre_consistency = true;
    else if (!std::strcmp(argv[a], "--no-centre-consistency")) popt.photo.centre_consistency = false;
    else if (is("--presmooth")) popt.photo.presmooth_sigma = std::atof(argv[++a]);
    else if (is("--mode")) {
      const std::string m = argv[++a];
      popt.dt_mode = m == "own"  ? DomainTransformMode::kOwnRecursive
                     : m == "rf" ? DomainTransformMode::kRecursive
                     : m == "ic" ? DomainTransformMode::kInterpolatedConvolution
                                 : DomainTransformMode::kNormalizedConvolution;
    } else if (is("--model")) {
      popt.model = std::string(argv[++a]) == "constant" ? PropagationModel::kConstant : PropagationModel::kAffine;
    } else if (!std::strcmp(argv[a], "--paper")) {
      popt = PaperPropagationOptions();
    } else if (!std::strcmp(argv[a], "--no-depth-confidence")) popt.weight_by_depth_confidence = false;
    else if (!std::strcmp(argv[a], "--no-keep-edge-depths")) popt.keep_edge_depths = false;
    else if (!std::strcmp(argv[a], "--no-inverse-depth")) popt.filter_inverse_depth = false;
    else if (!std::strcmp(argv[a], "--two-sided")) popt.one_sided_silhouettes = false;
    else if (is("--consistency-views")) popt.consistency.views = std::atoi(argv[++a]);
    else if (is("--refine-views")) popt.refinement.views = std::atoi(argv[++a]);
    else if (is("--refine-steps")) popt.refinement.steps = std::atoi(argv[++a]);
    else if (is("--refine-step-px")) popt.refinement.step_px = std::atof(argv[++a]);
    else if (is("--refine-radius")) popt.refinement.patch_radius_px = std::atoi(argv[++a]);
    else if (is("--refine-ncc-min")) popt.refinement.ncc_min = std::atof(argv[++a]);
    else if (!std::strcmp(argv[a], "--refine-fronto-parallel")) popt.refinement.slanted = false;
    else if (is("--consistency-min")) popt.consistency.rho_min = std::atof(argv[++a]);
    else if (is("--consistency-patch")) popt.consistency.patch_radius_px = std::atoi(argv[++a]);
    else if (!std::strcmp(argv[a], "--consistency-stats")) consistency_stats = true;
    else if (is("--consistency-sigma")) popt.consistency.sigma = std::atof(argv[++a]);
    else if (is("--ncc-radius")) popt.consistency.ncc_radius_px = std::atoi(argv[++a]);
    else if (is("--ncc-min")) popt.consistency.ncc_min = std::atof(argv[++a]);
    else if (is("--ncc-texture-min")) popt.consistency.ncc_texture_min = std::atof(argv[++a]);
    else if (!std::strcmp(argv[a], "--no-silhouette-splat-only")) popt.silhouette_pixels_splat_only = false;
    else if (!std::strcmp(argv[a], "--no-keep-blocked-silhouettes")) popt.blocked_silhouettes_keep_depth = false;
    else if (is("--ridge")) popt.affine_ridge_px = std::atof(argv[++a]);
    else if (is("--extrapolation-m0")) popt.extrapolation_m0 = std::atof(argv[++a]);
    else if (is("--extrapolation-floor")) popt.extrapolation_floor_px = std::atof(argv[++a]);
    else if (!std::strcmp(argv[a], "--oracle-depth")) oracle = true;
    else {
      std::fprintf(stderr, "unknown argument %s\n", argv[a]);
      return 2;
    }
  }
  popt.Check();
  spdlog::set_level(spdlog::level::warn);
  tbb::global_control control(tbb::global_control::max_allowed_parallelism, threads);
  cv::setNumThreads(threads);  // OpenCV's DTFilter runs on OpenCV's own thread pool
  const Dataset ds = Dataset::Open(dopt);
  std::vector<int> wanted;
  int seen = 0;
  for (int i = 0; i < ds.NumViews() && static_cast<int>(wanted.size()) < gt_views; ++i)
    if (ds.GroundTruthDepthPath(i) && seen++ >= skip && (seen - 1 - skip) % stride == 0) wanted.push_back(i);
  std::vector<PinholeView> views;
  std::vector<Eigen::Vector3d> dirs;
  for (int i = 0; i < ds.NumViews(); ++i) {
    views.push_back(ds.View(i));
    dirs.push_back(views.back().ViewingDirection());
  }
  const ViewGraph near(dirs, popt.photo.max_view_angle_deg);
  std::vector<PinholeView> dviews = views;  // the cameras densification sees (scaled by --upscale)
  for (PinholeView& v : dviews) {
    v.width *= upscale;
    v.height *= upscale;
    v.K.topRows<2>() *= upscale;
    v.K_inv = v.K.inverse();
  }
  auto random_frames = ds.OpenFrames();  // reference and neighbour frames, by random access
  DepthMetrics filtered_total, dense_total, dense_sparse_criterion, dense_loose[2];
  DepthMetricsOptions dense_opt;
  dense_opt.dense = true;
  double t_photo = 0, t_splat = 0, t_filter = 0, t_total = 0, t_cpu = 0;
  long long edge_pixels = 0, silhouette_pixels = 0, neighbours = 0;
  long long gt_fg_pixels = 0, gt_bg_pixels = 0, false_fg = 0, lost_fg = 0;
  double false_fg_conf = 0, lost_fg_conf = 0;
  double rho_hist[3][10] = {}, rho_conf[3][10] = {};
  long long false_fg_table = 0, false_fg_on_truth = 0, false_fg_above = 0;
  int done = 0;
  if (!preview_dir.empty()) fs::create_directories(preview_dir);
  Timer wall;
  const auto densify = [&](int i, const cv::Mat& image_in, const DepthMap& filtered_in) {
    // --upscale: frames (bicubic), maps and ground truth (nearest) and the
    // cameras scaled by an integer factor, to time a higher resolution.
    const auto up = [&](const cv::Mat& m, int interp) {
      if (upscale == 1 || m.empty()) return m;
      cv::Mat o;
      cv::resize(m, o, cv::Size(), upscale, upscale, interp);
      return o;
    };
    const cv::Mat image = up(image_in, cv::INTER_CUBIC);
    const auto read_gt = [&](int k) { return up(ReadDepthMap(*ds.GroundTruthDepthPath(k)), cv::INTER_NEAREST); };
    DepthMap filtered;
    filtered.depth = up(filtered_in.depth, cv::INTER_NEAREST);
    filtered.confidence = up(filtered_in.confidence, cv::INTER_NEAREST);
    filtered.label = up(filtered_in.label, cv::INTER_NEAREST);
    if (oracle) {
      // Diagnosis: the same pixels, with the true depth (what propagation alone loses).
      const cv::Mat gt = read_gt(i);
      filtered.depth = filtered.depth.clone();
      filtered.label = filtered.label.clone();
      for (int r = 0; r < gt.rows; ++r)
        for (int c = 0; c < gt.cols; ++c) {
          if (!(filtered.depth.at<float>(r, c) > 0) || !(gt.at<float>(r, c) > 0)) continue;
          const float t = gt.at<float>(r, c);
          filtered.depth.at<float>(r, c) = t;
          filtered.label.at<std::uint8_t>(r, c) = static_cast<std::uint8_t>(
              ds.bbox().Contains(dviews[i].Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), t)) ? DepthLabel::kForeground
                                                                                          : DepthLabel::kBackground);
        }
    }
    ViewImage ref;
    ref.view = dviews[i];
    ref.image = image;
    if (popt.photo.presmooth_sigma > 0)
      cv::GaussianBlur(ref.image, ref.smoothed, cv::Size(0, 0), popt.photo.presmooth_sigma);
    std::vector<ViewImage> nb_views;
    nb_views.reserve(near.Neighbors(i).size());
    for (int j : near.Neighbors(i)) {
      nb_views.emplace_back();
      nb_views.back().view = dviews[j];
      nb_views.back().image = up(random_frames->Read(j).image, cv::INTER_CUBIC);
      // The depth stage holds each frame with its pre-smoothed copy (same
      // 0.65 px Gaussian); the pipeline passes those, so they are not timed here.
      if (popt.photo.presmooth_sigma > 0)
        cv::GaussianBlur(nb_views.back().image, nb_views.back().smoothed, cv::Size(0, 0), popt.photo.presmooth_sigma);
    }
    std::vector<const ViewImage*> nbs;
    for (const ViewImage& v : nb_views) nbs.push_back(&v);
    const DepthPropagator propagator(popt);
    DenseDepthResult best;
    double best_total = 1e30;
    double best_cpu = 1e30;
    for (int k = 0; k < repeat; ++k) {
      Timer t;
      const std::clock_t c0 = std::clock();
      DenseDepthResult res = propagator.Run(ref, nbs, filtered, ds.bbox());
      const double cpu = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
      const double s = t.Seconds();
      best_cpu = std::min(best_cpu, cpu);
      if (s < best_total) {
        best_total = s;
        best = std::move(res);
      }
    }
    t_total += best_total;
    t_cpu += best_cpu;
    t_photo += best.seconds_photoconsistency;
    t_splat += best.seconds_splat;
    t_filter += best.seconds_filter;
    neighbours += static_cast<long long>(nbs.size());
    const cv::Mat classes = best.edges.Classify(popt.photo.silhouette_ratio);
    edge_pixels += cv::countNonZero(best.edges.evaluated);
    silhouette_pixels += cv::countNonZero(classes == static_cast<std::uint8_t>(EdgeClass::kSilhouette));
    const cv::Mat gt = read_gt(i);
    const DepthMetrics mf = EvaluateDepth(filtered, gt, image, dviews[i], ds.bbox(), DepthMetricsOptions());
    const DepthMetrics md = EvaluateDepth(best.dense, gt, image, dviews[i], ds.bbox(), dense_opt);
    const DepthMetrics ms = EvaluateDepth(best.dense, gt, image, dviews[i], ds.bbox(), DepthMetricsOptions());
    filtered_total.Add(mf);
    dense_total.Add(md);
    for (int k = 0; k < 2; ++k) {
      DepthMetricsOptions loose = dense_opt;
      loose.relative_tolerance = k == 0 ? 0.01 : 0.02;
      dense_loose[k].Add(EvaluateDepth(best.dense, gt, image, dviews[i], ds.bbox(), loose));
    }
    dense_sparse_criterion.Add(ms);
    cv::Mat rho;
    if (consistency_stats) {
      DenseConsistencyOptions co = popt.consistency;
      co.views = 4;
      DenseConsistencyAccumulator acc(co);
      std::vector<const PinholeView*> nvs;
      for (const ViewImage& v : nb_views) nvs.push_back(&v.view);
      acc.Begin(ref, best.dense);
      for (int j : acc.SelectNeighbors(ref.view, nvs)) acc.Add(nb_views[static_cast<std::size_t>(j)]);
      rho = acc.Finish();
      // ρ histograms: true foreground within 1 % / beyond, true background labelled foreground.
      for (int r = 0; r < gt.rows; ++r)
        for (int c = 0; c < gt.cols; ++c) {
          const float t = gt.at<float>(r, c), q = rho.at<float>(r, c);
          if (!(t > 0) || q < 0) continue;
          const bool true_fg = ds.bbox().Contains(dviews[i].Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), t));
          const float e = best.dense.depth.at<float>(r, c);
          const int cls = !true_fg ? 2 : std::abs(e - t) <= 0.01 * t ? 0 : 1;
          rho_hist[cls][std::min(9, static_cast<int>(q * 10))] += 1;
          rho_conf[cls][std::min(9, static_cast<int>(q * 10))] += best.dense.confidence.at<float>(r, c);
        }
    }
    {
      // Labels against the truth: ground-truth background pixels (true point
      // outside V) labelled foreground are what fusion turns into surface
      // that is not there (false foreground); ground-truth foreground pixels
      // labelled background are what it carves (lost foreground).
      for (int r = 0; r < gt.rows; ++r)
        for (int c = 0; c < gt.cols; ++c) {
          const float t = gt.at<float>(r, c);
          if (!(t > 0)) continue;
          const bool true_fg = ds.bbox().Contains(dviews[i].Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), t));
          const float e = best.dense.depth.at<float>(r, c);
          const std::uint8_t l = best.dense.label.at<std::uint8_t>(r, c);
          const bool fg = e > 0 && l == static_cast<std::uint8_t>(DepthLabel::kForeground);
          const bool bgl = e > 0 && l == static_cast<std::uint8_t>(DepthLabel::kBackground);
          (true_fg ? gt_fg_pixels : gt_bg_pixels)++;
          if (!true_fg && fg) {
            ++false_fg;
            false_fg_conf += best.dense.confidence.at<float>(r, c);
            // Where: the table under V (true z within 3 mm of V's floor), and
            // whether the estimate sits on the true point (within 1 %).
            const Eigen::Vector3d x = dviews[i].Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), t);
            const bool table = std::abs(x.z() - ds.bbox().min.z()) < 0.003 && x.x() >= ds.bbox().min.x() &&
                               x.x() <= ds.bbox().max.x() && x.y() >= ds.bbox().min.y() && x.y() <= ds.bbox().max.y();
            false_fg_table += table;
            false_fg_on_truth += std::abs(e - t) <= 0.01 * t;
            const Eigen::Vector3d xe = dviews[i].Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), e);
            false_fg_above += xe.z() - ds.bbox().min.z() > 0.005;
          }
          if (true_fg && bgl) {
            ++lost_fg;
            lost_fg_conf += best.dense.confidence.at<float>(r, c);
          }
        }
    }
    if (getenv("LFRECON_BENCH_DIAG")) {
      // Dense accuracy over ground-truth foreground pixels by distance to the
      // nearest pixel with a filtered depth, and the label of wrong ones.
      cv::Mat no_depth = filtered.depth <= 0, dist;
      cv::distanceTransform(no_depth, dist, cv::DIST_L2, 3);
      const double edges[5] = {0.5, 1.5, 3.5, 8.5, 1e9};
      long long n[5] = {0}, ok[5] = {0}, bg[5] = {0}, none[5] = {0}, own_ok[5] = {0}, own_n[5] = {0};
      for (int r = 0; r < gt.rows; ++r)
        for (int c = 0; c < gt.cols; ++c) {
          const float t = gt.at<float>(r, c);
          if (!(t > 0)) continue;
          BoundingBox inner = ds.bbox();
          inner.min.array() += 0.001;
          inner.max.array() -= 0.001;
          if (!inner.Contains(dviews[i].Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), t))) continue;
          int b = 0;
          while (dist.at<float>(r, c) > edges[b]) ++b;
          ++n[b];
          const float e = best.dense.depth.at<float>(r, c);
          if (!(e > 0)) { ++none[b]; continue; }
          ok[b] += std::abs(e - t) <= 0.005 * t;
          bg[b] += best.dense.label.at<std::uint8_t>(r, c) == static_cast<std::uint8_t>(DepthLabel::kBackground);
          const float f = filtered.depth.at<float>(r, c);
          if (f > 0) { ++own_n[b]; own_ok[b] += std::abs(f - t) <= 0.005 * t; }
        }
      for (int b = 0; b < 5; ++b)
        std::printf("  dist<=%.1f: %lld px (%.1f%%), dense ok %.3f, bg-labelled %.3f, none %.3f, filtered ok %.3f\n",
                    edges[b], n[b], 100.0 * n[b] / std::max(1LL, md.expected), n[b] ? double(ok[b]) / n[b] : 0,
                    n[b] ? double(bg[b]) / n[b] : 0, n[b] ? double(none[b]) / n[b] : 0,
                    own_n[b] ? double(own_ok[b]) / own_n[b] : 0);
    }
    std::printf("view %4d: filtered accuracy %.3f coverage %.3f | dense accuracy %.3f coverage %.3f "
                "(edge pixels only: %.3f) | %.1f ms (photo %.1f, splat %.1f, filter %.1f, refine %.1f), %zu neighbours\n",
                i, mf.Accuracy(), mf.Coverage(), md.Accuracy(), md.Coverage(), ms.Accuracy(), 1000 * best_total,
                1000 * best.seconds_photoconsistency, 1000 * best.seconds_splat, 1000 * best.seconds_filter,
                1000 * best.seconds_refinement, nbs.size());
    if (!preview_dir.empty()) {
      const std::string stem = fs::path(ds.views()[i].name).stem().string();
      WriteEdgePreview(fs::path(preview_dir) / ("propagation_edges_" + stem + ".png"), image, classes);
      WriteDepthPreview(fs::path(preview_dir) / ("propagation_dense_" + stem + ".png"), best.dense.depth, image);
      if (getenv("LFRECON_BENCH_DIAG")) {
        // Error map over ground-truth foreground: green within 0.5 %, yellow
        // within 2 %, red beyond, blue where the background side won; grey frame elsewhere.
        cv::Mat err;
        image.convertTo(err, CV_8UC3, 120.0);
        cv::hconcat(err, err.clone(), err);
        for (int r = 0; r < gt.rows; ++r)
          for (int c = 0; c < gt.cols; ++c) {
            const float t = gt.at<float>(r, c);
            if (t > 0 && !ds.bbox().Contains(dviews[i].Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), t))) {
              // True background labelled foreground (false foreground): magenta.
              for (int k = 0; k < 2; ++k) {
                const DepthMap& m = k == 0 ? best.dense : filtered;
                if (m.depth.at<float>(r, c) > 0 &&
                    m.label.at<std::uint8_t>(r, c) == static_cast<std::uint8_t>(DepthLabel::kForeground))
                  err.at<cv::Vec3b>(r, c + k * gt.cols) = cv::Vec3b(255, 0, 255);
              }
              continue;
            }
            if (!(t > 0) || !ds.bbox().Contains(dviews[i].Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), t)) ||
                dviews[i].Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), t).z() < 0.001)
              continue;
            for (int k = 0; k < 2; ++k) {
              const DepthMap& m = k == 0 ? best.dense : filtered;
              const float e = m.depth.at<float>(r, c);
              cv::Vec3b col(80, 80, 80);
              if (e > 0) {
                const double rel = std::abs(e - t) / t;
                col = m.label.at<std::uint8_t>(r, c) == static_cast<std::uint8_t>(DepthLabel::kBackground)
                          ? cv::Vec3b(255, 0, 0)
                          : rel <= 0.005 ? cv::Vec3b(0, 200, 0) : rel <= 0.02 ? cv::Vec3b(0, 220, 255) : cv::Vec3b(0, 0, 255);
              }
              err.at<cv::Vec3b>(r, c + k * gt.cols) = col;
            }
          }
        cv::imwrite((fs::path(preview_dir) / ("propagation_error_" + stem + ".png")).string(), err);
      }
    }
    std::fflush(stdout);
    ++done;
  };

  // Filtered maps: from the cache folder when all are there, else StreamingDepth (and fill the cache).
  const auto cached = [&](int i, const char* what) {
    return fs::path(cache_dir) / (std::to_string(i) + "_" + what + (std::string(what) == "label" ? ".png" : ".pfm"));
  };
  bool all_cached = !cache_dir.empty();
  for (int i : wanted)
    for (const char* w : {"depth", "confidence", "label"}) all_cached = all_cached && fs::exists(cached(i, w));
  StreamingDepthStats stats;
  if (all_cached) {
    for (int i : wanted) {
      DepthMap m;
      m.depth = ReadPfm(cached(i, "depth"));
      m.confidence = ReadPfm(cached(i, "confidence"));
      m.label = cv::imread(cached(i, "label").string(), cv::IMREAD_UNCHANGED);
      densify(i, random_frames->Read(i).image, m);
    }
  } else {
    if (!cache_dir.empty()) fs::create_directories(cache_dir);
    auto frames = ds.OpenFrames();
    StreamingDepth stage(views, ds.bbox(), sopt);
    stats = stage.Run(*frames, wanted, [&](int i, const cv::Mat& image, const DepthMap&, const DepthMap& filtered) {
      if (!cache_dir.empty()) {
        WritePfm(cached(i, "depth"), filtered.depth);
        WritePfm(cached(i, "confidence"), filtered.confidence);
        cv::imwrite(cached(i, "label").string(), filtered.label);
      }
      densify(i, image, filtered);
    });
  }
  const int n = std::max(1, done);
  std::printf("views %d, %dx%d, threads %d: dense %.1f ms/view wall, %.1f ms/view CPU (all threads); wall: "
              "photoconsistency %.1f, splat %.1f, filter %.1f; "
              "%.0f edge pixels/view (%.1f%% silhouette), %.1f neighbours/view; sparse %.0f ms/view, filter %.0f "
              "ms/view; total %.1f s, peak RSS %.0f MiB\n",
              done, dviews.empty() ? 0 : dviews[0].width, dviews.empty() ? 0 : dviews[0].height, threads,
              1000 * t_total / n, 1000 * t_cpu / n, 1000 * t_photo / n, 1000 * t_splat / n, 1000 * t_filter / n,
              static_cast<double>(edge_pixels) / n, 100.0 * silhouette_pixels / std::max(1LL, edge_pixels),
              static_cast<double>(neighbours) / n, 1000 * stats.seconds_sparse / std::max(1, stats.sparse_maps),
              1000 * stats.seconds_filter / std::max(1, stats.filtered_maps), wall.Seconds(),
              PeakRssBytes() / 1048576.0);
  PrintCurve("filtered (edge pixels)", filtered_total);
  PrintCurve("dense (edge pixels)", dense_sparse_criterion);
  PrintCurve("dense (all foreground pixels)", dense_total);
  if (consistency_stats) {
    const char* names[3] = {"true fg, depth within 1%", "true fg, depth off", "false fg (true background)"};
    for (int k = 0; k < 3; ++k) {
      double n = 0, w = 0;
      for (int b = 0; b < 10; ++b) n += rho_hist[k][b], w += rho_conf[k][b];
      std::printf("rho %-28s:", names[k]);
      for (int b = 0; b < 10; ++b) std::printf(" %.3f", rho_hist[k][b] / std::max(1.0, n));
      std::printf("  | by confidence:");
      for (int b = 0; b < 10; ++b) std::printf(" %.3f", rho_conf[k][b] / std::max(1e-9, w));
      std::printf("  (%.0f px)\n", n);
    }
  }
  std::printf("labels: false foreground %.4f of true background pixels (summed confidence %.1f per view), "
              "lost foreground %.4f of true foreground pixels (summed confidence %.1f per view)\n",
              double(false_fg) / std::max(1LL, gt_bg_pixels), false_fg_conf / std::max(1, done),
              double(lost_fg) / std::max(1LL, gt_fg_pixels), lost_fg_conf / std::max(1, done));
  std::printf("  false foreground: %.3f on the table under V, %.3f within 1 %% of the true depth, %.3f put "
              "more than 5 mm above V's floor\n",
              double(false_fg_table) / std::max(1LL, false_fg), double(false_fg_on_truth) / std::max(1LL, false_fg),
              double(false_fg_above) / std::max(1LL, false_fg));
  std::printf("dense (all foreground pixels) within 1%%: accuracy %.4f; within 2%%: accuracy %.4f\n",
              dense_loose[0].Accuracy(), dense_loose[1].Accuracy());
  return 0;
}
