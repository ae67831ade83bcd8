// Benchmark (not a test): sparse depth from gradients (§3.1) of a few views,
// as the pipeline computes it (neighbours chosen by SelectHierarchyViews on
// the sequence's HierarchyGrid), for profiling and for checking that a speed-up
// leaves the output unchanged.
//   sparse_depth_bench DATASET [--views 8,16] [--threads 1] [--repeat N]
//                      [--out DIR] [--ref DIR]
// --out: writes DIR/sparse_NNNN.bin per view (rows, cols, then depth and
// confidence as float32 and the label as uint8, row-major).
// --ray-stats: how many depths lie on rays that miss V (grown by 0-50 %).
// --every-level: settle_outside_volume off (every level for every pixel).
// --resample-reference: reuse_reference_patch off (the reference side of a
//   later level's patches sampled again at each reference point's depth).
// --ref: compares each view with DIR/sparse_NNNN.bin from an earlier run:
// pixels whose depth, confidence or label differ, max |Δdepth| (absolute and
// relative) and max |Δconfidence|; exit status 1 when a map is missing.
// Only GradientDepthEstimator::Estimate is timed (frames are read first), so
// `valgrind --tool=callgrind --toggle-collect='lfrecon::GradientDepthEstimator::Estimate*'`
// with --threads 1 counts the estimator's instructions alone.
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <deque>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>

#include "depth/gradient_depth_estimator.h"
#include "io/dataset.h"
#include "util/progress.h"

using namespace lfrecon;

namespace {

bool WriteMap(const std::string& path, const DepthMap& m) {
  std::ofstream f(path, std::ios::binary);
  const int rows = m.depth.rows, cols = m.depth.cols;
  f.write(reinterpret_cast<const char*>(&rows), sizeof rows);
  f.write(reinterpret_cast<const char*>(&cols), sizeof cols);
  f.write(reinterpret_cast<const char*>(m.depth.ptr<float>()), sizeof(float) * rows * cols);
  f.write(reinterpret_cast<const char*>(m.confidence.ptr<float>()), sizeof(float) * rows * cols);
  f.write(reinterpret_cast<const char*>(m.label.ptr<std::uint8_t>()), rows * cols);
  return static_cast<bool>(f);
}

bool ReadMap(const std::string& path, DepthMap* m) {
  std::ifstream f(path, std::ios::binary);
  int rows = 0, cols = 0;
  f.read(reinterpret_cast<char*>(&rows), sizeof rows);
  f.read(reinterpret_cast<char*>(&cols), sizeof cols);
  if (!f || rows <= 0 || cols <= 0) return false;
  *m = DepthMap(rows, cols);
  f.read(reinterpret_cast<char*>(m->depth.ptr<float>()), sizeof(float) * rows * cols);
  f.read(reinterpret_cast<char*>(m->confidence.ptr<float>()), sizeof(float) * rows * cols);
  f.read(reinterpret_cast<char*>(m->label.ptr<std::uint8_t>()), rows * cols);
  return static_cast<bool>(f);
}

}  // namespace


// Of the map's depths, how many lie on rays that miss V grown by 0, 10, 25
// and 50 % of its largest extent on every side: pixels whose depth can never
// be a point of V (or near it).
void PrintRayStats(const PinholeView& view, const DepthMap& map, const BoundingBox& volume) {
  const double margins[] = {0.0, 0.1, 0.25, 0.5};
  long long miss[4] = {0, 0, 0, 0}, total = 0;
  const Eigen::Vector3d centre = view.Center();
  for (int r = 0; r < map.depth.rows; ++r)
    for (int c = 0; c < map.depth.cols; ++c) {
      if (!(map.depth.at<float>(r, c) > 0)) continue;
      ++total;
      const Eigen::Vector3d dir = view.Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), 1.0) - centre;
      for (int m = 0; m < 4; ++m) {
        BoundingBox grown = volume;
        const double g = margins[m] * volume.Extent().maxCoeff();
        grown.min.array() -= g;
        grown.max.array() += g;
        miss[m] += !RayMeetsBox(centre, dir, grown);
      }
    }
  std::printf("  depths on rays that miss V grown by 0 / 10 / 25 / 50 %%: %.1f / %.1f / %.1f / %.1f %% of %lld\n",
              100.0 * miss[0] / std::max(total, 1LL), 100.0 * miss[1] / std::max(total, 1LL),
              100.0 * miss[2] / std::max(total, 1LL), 100.0 * miss[3] / std::max(total, 1LL), total);
}

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: %s DATASET [--views 8,16] [--threads 1] [--repeat N] [--out DIR] [--ref DIR]\n",
                 argv[0]);
    return 2;
  }
  DatasetOptions dopt;
  dopt.dataset_dir = argv[1];
  std::vector<int> wanted = {8};
  int threads = 1, repeat = 1;
  std::string out_dir, ref_dir;
  bool ray_stats = false;
  bool every_level = false;
  bool resample_reference = false;
  for (int a = 2; a < argc; ++a) {
    if (!std::strcmp(argv[a], "--views") && a + 1 < argc) {
      wanted.clear();
      std::stringstream ss(argv[++a]);
      std::string item;
      while (std::getline(ss, item, ',')) wanted.push_back(std::stoi(item));
    } else if (!std::strcmp(argv[a], "--threads") && a + 1 < argc) {
      threads = std::atoi(argv[++a]);
    } else if (!std::strcmp(argv[a], "--repeat") && a + 1 < argc) {
      repeat = std::max(1, std::atoi(argv[++a]));
    } else if (!std::strcmp(argv[a], "--out") && a + 1 < argc) {
      out_dir = argv[++a];
    } else if (!std::strcmp(argv[a], "--ref") && a + 1 < argc) {
      ref_dir = argv[++a];
    } else if (!std::strcmp(argv[a], "--ray-stats")) {
      ray_stats = true;
    } else if (!std::strcmp(argv[a], "--every-level")) {
      every_level = true;
    } else if (!std::strcmp(argv[a], "--resample-reference")) {
      resample_reference = true;
    } else {
      std::fprintf(stderr, "unknown or incomplete option %s\n", argv[a]);
      return 2;
    }
  }
  spdlog::set_level(spdlog::level::warn);
  tbb::global_control control(tbb::global_control::max_allowed_parallelism, threads);
  const Dataset ds = Dataset::Open(dopt);
  GradientDepthOptions options;
  options.settle_outside_volume = !every_level;
  options.reuse_reference_patch = !resample_reference;
  std::vector<PinholeView> views;
  for (int i = 0; i < ds.NumViews(); ++i) views.push_back(ds.View(i));
  const std::vector<char> grid = HierarchyGrid(views, options);
  std::vector<const PinholeView*> all;
  for (const PinholeView& v : views) all.push_back(&v);
  auto frames = ds.OpenFrames();
  const GradientDepthEstimator estimator(options);
  int status = 0;
  double total_s = 0;
  for (int i : wanted) {
    if (i < 0 || i >= ds.NumViews()) {
      std::fprintf(stderr, "view %d out of range\n", i);
      return 2;
    }
    // The reference and its neighbours, prepared as StreamingDepth holds them.
    ViewImage reference;
    reference.view = views[i];
    reference.image = frames->Read(i).image;
    reference.on_grid = grid[i];
    PrepareViewImage(&reference, options);
    std::deque<ViewImage> held;
    std::vector<const ViewImage*> nbs;
    for (int q : SelectHierarchyViews(views[i], all, grid, options)) {
      if (q == i) continue;
      ViewImage& v = held.emplace_back();
      v.view = views[q];
      v.image = frames->Read(q).image;
      v.on_grid = grid[q];
      PrepareViewImage(&v, options);
      v.image = v.smoothed;
      nbs.push_back(&v);
    }
    DepthMap map;
    Timer timer;
    for (int r = 0; r < repeat; ++r) map = estimator.Estimate(reference, nbs, ds.bbox());
    const double seconds = timer.Seconds() / repeat;
    total_s += seconds;
    std::printf("view %4d: %zu neighbours, %d depths, %.1f ms\n", i, nbs.size(), map.CountValid(), 1000 * seconds);
    if (ray_stats) PrintRayStats(views[i], map, ds.bbox());
    char name[64];
    std::snprintf(name, sizeof name, "/sparse_%04d.bin", i);
    if (!out_dir.empty() && !WriteMap(out_dir + name, map)) {
      std::fprintf(stderr, "cannot write %s%s\n", out_dir.c_str(), name);
      status = 1;
    }
    if (!ref_dir.empty()) {
      DepthMap ref;
      if (!ReadMap(ref_dir + name, &ref) || ref.depth.size() != map.depth.size()) {
        std::fprintf(stderr, "no reference %s%s of this size\n", ref_dir.c_str(), name);
        status = 1;
        continue;
      }
      long long diff = 0, depth_diff = 0, valid_diff = 0, label_diff = 0, both = 0;
      double max_abs = 0, max_rel = 0, max_conf = 0;
      for (int r = 0; r < map.depth.rows; ++r)
        for (int c = 0; c < map.depth.cols; ++c) {
          const float a = map.depth.at<float>(r, c), b = ref.depth.at<float>(r, c);
          const float ca = map.confidence.at<float>(r, c), cb = ref.confidence.at<float>(r, c);
          const bool la = map.label.at<std::uint8_t>(r, c) != ref.label.at<std::uint8_t>(r, c);
          if ((a > 0) != (b > 0)) ++valid_diff;
          if (a > 0 && b > 0) {
            ++both;
            max_abs = std::max(max_abs, static_cast<double>(std::abs(a - b)));
            max_rel = std::max(max_rel, static_cast<double>(std::abs(a - b) / b));
            max_conf = std::max(max_conf, static_cast<double>(std::abs(ca - cb)));
          }
          if (a != b) ++depth_diff;
          if (la) ++label_diff;
          if (a != b || ca != cb || la) ++diff;
        }
      std::printf("  vs reference: %lld pixels differ (depth %lld, label %lld, set in one only %lld) of %lld set in both; "
                  "max |d depth| %.3g m (relative %.3g), max |d confidence| %.3g\n",
                  diff, depth_diff, label_diff, valid_diff, both, max_abs, max_rel, max_conf);
    }
  }
  std::printf("estimate total %.1f ms for %zu views, threads %d\n", 1000 * total_s, wanted.size(), threads);
  return status;
}
