// Benchmark (not a test): where thin parts are lost between the depth stages.
//   thin_stage_bench DATASET LABEL=DEPTH_DIR [LABEL=DEPTH_DIR ...] [--tolerance-mm T] [--radius-px R]
// DEPTH_DIR holds <image-stem>.pfm depth maps (as `lfrecon depth --stage sparse|filtered|dense`
// or `lfrecon run --write-depth` write them; confidence/ beside them is not needed). For every
// view with ground-truth depth and a map in each DEPTH_DIR, the dataset's thin ground truth
// (gt_thin.ply, sampled every 1 mm) is projected into the view; a sample the ground-truth depth
// sees unoccluded is *covered* by a stage when a pixel within R px (default 1) of its
// projection has a depth within T mm (default 5) of the sample's. Prints, per stage, the share
// of visible thin samples covered, overall and per thin part (connected components of samples
// on a 4 mm grid, largest first), so a part missing from the mesh can be traced to the stage that lost it.
#include <Eigen/Core>
#include <opencv2/core.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <string>
#include <vector>

#include "eval/mesh_metrics.h"
#include "grid_components.h"
#include "io/dataset.h"
#include "io/depth_map_io.h"
#include "io/ply.h"

using namespace lfrecon;
namespace fs = std::filesystem;

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s DATASET LABEL=DEPTH_DIR [LABEL=DEPTH_DIR ...] [--tolerance-mm T] [--radius-px R]\n",
                 argv[0]);
    return 2;
  }
  DatasetOptions dopt;
  dopt.dataset_dir = argv[1];
  double tolerance = 0.005;
  int radius = 1;
  int dump_view = -1, dump_count = 3;  // --dump-view I: depth windows around thin samples of view I
  std::vector<std::pair<std::string, fs::path>> stages;
  for (int a = 2; a < argc; ++a) {
    if (!std::strcmp(argv[a], "--tolerance-mm") && a + 1 < argc) tolerance = std::atof(argv[++a]) / 1000.0;
    else if (!std::strcmp(argv[a], "--radius-px") && a + 1 < argc) radius = std::atoi(argv[++a]);
    else if (!std::strcmp(argv[a], "--dump-view") && a + 1 < argc) dump_view = std::atoi(argv[++a]);
    else if (!std::strcmp(argv[a], "--dump-count") && a + 1 < argc) dump_count = std::atoi(argv[++a]);
    else {
      const std::string s = argv[a];
      const auto eq = s.find('=');
      if (eq == std::string::npos) {
        std::fprintf(stderr, "expected LABEL=DEPTH_DIR, got '%s'\n", argv[a]);
        return 2;
      }
      stages.emplace_back(s.substr(0, eq), fs::path(s.substr(eq + 1)));
    }
  }
  const Dataset ds = Dataset::Open(dopt);
  const auto thin_path = ds.GroundTruthMeshPath(true);
  if (!thin_path) {
    std::fprintf(stderr, "%s has no gt_thin.ply\n", argv[1]);
    return 2;
  }
  const std::vector<Eigen::Vector3d> pts = SampleSurface(ReadPly(*thin_path), 0.001, 1);
  const ObservationOptions observation;
  int num_clusters = 0;
  const std::vector<int> cluster = bench::GridComponents(pts, 0.004, &num_clusters);
  // visible[c], covered[s][c]: sample-view pairs per cluster.
  std::vector<long long> visible(num_clusters, 0);
  std::vector<std::vector<long long>> covered(stages.size(), std::vector<long long>(num_clusters, 0));
  std::vector<long long> empty(stages.size(), 0), far(stages.size(), 0);  // misses: no depth near / one behind
  int views_used = 0, dumped = 0;
  for (int i = 0; i < ds.NumViews(); ++i) {
    const auto gt_path = ds.GroundTruthDepthPath(i);
    if (!gt_path) continue;
    const std::string stem = fs::path(ds.views()[i].name).stem().string();
    std::vector<cv::Mat> maps;
    for (const auto& [label, dir] : stages) {
      const fs::path p = dir / (stem + ".pfm");
      if (!fs::exists(p)) break;
      maps.push_back(ReadPfm(p));
    }
    if (maps.size() != stages.size()) continue;
    ++views_used;
    const cv::Mat gt = ReadDepthMap(*gt_path);
    const PinholeView view = ds.View(i);
    for (size_t n = 0; n < pts.size(); ++n) {
      Eigen::Vector2d px;
      const double z = view.Project(pts[n], &px);
      if (z <= 0 || !view.InImage(px)) continue;
      const int x = static_cast<int>(px.x()), y = static_cast<int>(px.y());
      // Visible: the ground-truth depth at its pixel is its own, within the
      // observation mask's tolerance (ObservationOptions: max(2 mm, 0.25 %)).
      if (!(std::abs(gt.at<float>(y, x) - z) <= std::max(observation.tolerance, observation.relative_tolerance * z)))
        continue;
      ++visible[cluster[n]];
      for (size_t s = 0; s < maps.size(); ++s) {
        bool hit = false, any = false, behind = false;
        for (int dy = -radius; dy <= radius && !hit; ++dy)
          for (int dx = -radius; dx <= radius && !hit; ++dx) {
            const int xx = x + dx, yy = y + dy;
            if (xx < 0 || yy < 0 || xx >= maps[s].cols || yy >= maps[s].rows) continue;
            const float d = maps[s].at<float>(yy, xx);
            if (!(d > 0)) continue;
            any = true;
            behind |= d > z + tolerance;
            hit = std::abs(d - z) <= tolerance;
          }
        if (hit) ++covered[s][cluster[n]];
        else if (!any) ++empty[s];
        else if (behind) ++far[s];
      }
      if (i == dump_view && n % 997 == 0 && dumped < dump_count * 40) {
        ++dumped;
        std::printf("view %d sample (%.3f %.3f %.3f) at px (%d, %d), depth %.4f; window 7x7 (mm from it):\n", i,
                    pts[n].x(), pts[n].y(), pts[n].z(), x, y, z);
        auto show = [&](const char* label, const cv::Mat& m) {
          std::printf("  %s\n", label);
          for (int dy = -3; dy <= 3; ++dy) {
            std::printf("   ");
            for (int dx = -3; dx <= 3; ++dx) {
              const int xx = x + dx, yy = y + dy;
              const float d = (xx < 0 || yy < 0 || xx >= m.cols || yy >= m.rows) ? 0.f : m.at<float>(yy, xx);
              if (d > 0) std::printf(" %7.0f", (d - z) * 1000.0);
              else std::printf(" %7s", ".");
            }
            std::printf("\n");
          }
        };
        show("ground truth", gt);
        for (size_t s = 0; s < maps.size(); ++s) show(stages[s].first.c_str(), maps[s]);
      }
    }
  }
  std::printf("%d views with ground truth and a map in every folder; %zu thin samples, %d parts\n", views_used,
              pts.size(), num_clusters);
  long long vis_all = 0;
  for (long long v : visible) vis_all += v;
  std::printf("%-34s %10s", "part (centroid m, extent mm)", "visible");
  for (const auto& st : stages) std::printf(" %9s", st.first.c_str());
  std::printf("\n%-34s %10lld", "all", vis_all);
  for (size_t s = 0; s < stages.size(); ++s) {
    long long c = 0;
    for (long long v : covered[s]) c += v;
    std::printf(" %9.3f", vis_all ? static_cast<double>(c) / vis_all : 0.0);
  }
  std::printf("\n%-34s %10s", "missed: no depth within R px", "");
  for (size_t s = 0; s < stages.size(); ++s) std::printf(" %9.3f", vis_all ? static_cast<double>(empty[s]) / vis_all : 0.0);
  std::printf("\n%-34s %10s", "missed: a depth behind it", "");
  for (size_t s = 0; s < stages.size(); ++s) std::printf(" %9.3f", vis_all ? static_cast<double>(far[s]) / vis_all : 0.0);
  std::printf("\n");
  std::vector<int> order(num_clusters);
  for (int c = 0; c < num_clusters; ++c) order[c] = c;
  std::sort(order.begin(), order.end(), [&](int a, int b) { return visible[a] > visible[b]; });
  for (int c : order) {
    if (visible[c] < 0.005 * vis_all) break;
    Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e9), hi = -lo, sum = Eigen::Vector3d::Zero();
    int m = 0;
    for (size_t n = 0; n < pts.size(); ++n)
      if (cluster[n] == c) {
        lo = lo.cwiseMin(pts[n]);
        hi = hi.cwiseMax(pts[n]);
        sum += pts[n];
        ++m;
      }
    const Eigen::Vector3d ctr = sum / std::max(m, 1), ext = (hi - lo) * 1000.0;
    char name[64];
    std::snprintf(name, sizeof(name), "(%.3f %.3f %.3f) %3.0fx%3.0fx%3.0f", ctr.x(), ctr.y(), ctr.z(), ext.x(), ext.y(),
                  ext.z());
    std::printf("%-34s %10lld", name, visible[c]);
    for (size_t s = 0; s < stages.size(); ++s)
      std::printf(" %9.3f", visible[c] ? static_cast<double>(covered[s][c]) / visible[c] : 0.0);
    std::printf("\n");
  }
  return 0;
}
