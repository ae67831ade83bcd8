// Fusion (§5) of depth maps already on disk — e.g. `lfrecon run --write-depth`
// or `lfrecon depth --stage dense` output — for several values of σ_s, scored
// against the dataset's ground-truth mesh. Tunes fusion without re-running
// the depth stages (which take most of a run).
//
//   fusion_from_depth_bench DATASET DEPTH_OUT [--sigma-s 0.1,0.15,0.2] [--voxel-mm 2] [--activation-min-confidence 0.01]
//       [--refine 1] [--analyze 1] [--keep-mesh DIR]   (run without options for all of them)
//   fusion_from_depth_bench DATASET - --mesh MESH.ply   (scores and analyses one mesh: where its error lies)
//   fusion_from_depth_bench DATASET DEPTH_OUT --probability-clamp 0.03 --geo-consistency 2/4/8/16,4,0.01
//       (diagnosis: drop the foreground depths that fewer than 4 of the maps 2, 4, 8, 16 before and after
//        agree with within 1 %, then fuse; docs/benchmarks.md "Multi-view geometric consistency")
//   fusion_from_depth_bench DATASET DEPTH_OUT --probability-clamp 0.03 --score 0 [--max-views N] [--keep-mesh DIR]
//       (the cost of fusion alone with `lfrecon run`'s fusion options: Integrate and ExtractMesh timed per phase,
//        no scoring; N: every k-th map so that at most N are fused. Under valgrind, count only the fusion with
//        --toggle-collect='*ProbabilisticFusion::Integrate*' --toggle-collect='*ProbabilisticFusion::ExtractMesh*'
//        and --threads 1: with more threads TBB's split of the work, and so the count, varies from run to run)
//
// DEPTH_OUT holds depth/<stem>.pfm and confidence/<stem>.pfm; labels are not
// stored, so a depth is foreground when its point lies inside V.
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <mutex>
#include <unordered_map>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include "eval/mesh_metrics.h"
#include "grid_components.h"
#include "nearest_triangle.h"
#include "fusion/free_space.h"
#include "fusion/geometric_consistency.h"
#include "fusion/probabilistic_fusion.h"
#include "fusion/surface_evidence.h"
#include "io/dataset.h"
#include "io/depth_map_io.h"
#include "io/ply.h"
#include "propagation/dense_consistency.h"
#include "propagation/depth_propagator.h"
#include "util/progress.h"
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include "refine/mesh_cleanup.h"
#include "refine/refine.h"

using namespace lfrecon;
using lfrecon::bench::NearestTriangle;
namespace fs = std::filesystem;

// ---- Where the error is (--analyze / --mesh): per-sample distances to the ground truth, split by kind.
namespace {

struct Cluster {
  std::size_t n = 0, outside = 0;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero(), lo = Eigen::Vector3d::Constant(1e9), hi = -Eigen::Vector3d::Constant(1e9);
  double dist = 0;
  Eigen::Vector3d rep = Eigen::Vector3d::Zero();  // the member nearest the centroid
};

// Connected components (26-neighbourhood) of points on a grid of `cell`.
std::vector<Cluster> ClusterPoints(const std::vector<Eigen::Vector3d>& pts, const std::vector<double>& sd, double cell) {
  int count = 0;
  const std::vector<int> label = bench::GridComponents(pts, cell, &count);
  std::vector<Cluster> out(count);
  for (std::size_t i = 0; i < pts.size(); ++i) {
    Cluster& cl = out[label[i]];
    ++cl.n;
    cl.sum += pts[i];
    cl.lo = cl.lo.cwiseMin(pts[i]);
    cl.hi = cl.hi.cwiseMax(pts[i]);
    cl.dist += std::isfinite(sd[i]) ? std::abs(sd[i]) : 0.05;
    if (sd[i] > 0) ++cl.outside;
  }
  for (std::size_t i = 0; i < pts.size(); ++i) {
    Cluster& c = out[label[i]];
    const Eigen::Vector3d m = c.sum / c.n;
    if (c.rep.isZero() || (pts[i] - m).norm() < (c.rep - m).norm()) c.rep = pts[i];
  }
  std::sort(out.begin(), out.end(), [](const Cluster& a, const Cluster& b) { return a.n > b.n; });
  return out;
}

void AnalyzeMesh(const std::string& name, const TriangleMesh& mesh, const TriangleMesh& gt, const TriangleMesh* thin,
                 const BoundingBox& volume) {
  const double tau = 0.005;
  std::vector<Eigen::Vector3d> pred = SampleSurface(mesh, 0.001, 1);
  pred.erase(std::remove_if(pred.begin(), pred.end(), [&](const Eigen::Vector3d& p) { return !volume.Contains(p); }),
             pred.end());
  const NearestTriangle to_gt(gt, 0.01, 6);
  std::vector<double> sd(pred.size());
  tbb::parallel_for(std::size_t{0}, pred.size(), [&](std::size_t i) { sd[i] = to_gt.Signed(pred[i]); });
  const double bands[] = {0.002, 0.005, 0.010, 0.020, 0.040, 1e9};
  std::size_t cnt[6][2] = {};
  std::size_t table = 0, table_far = 0;
  std::vector<Eigen::Vector3d> far;
  std::vector<double> far_sd;
  for (std::size_t i = 0; i < pred.size(); ++i) {
    const double a = std::isfinite(sd[i]) ? std::abs(sd[i]) : 1e8;
    int b = 0;
    while (a >= bands[b]) ++b;
    ++cnt[b][sd[i] > 0 ? 1 : 0];
    if (pred[i].z() < 0.004) {
      ++table;
      if (a >= tau) ++table_far;
    }
    if (a >= tau) {
      far.push_back(pred[i]);
      far_sd.push_back(sd[i]);
    }
  }
  const double n = static_cast<double>(pred.size());
  std::printf("[%s] %zu samples in V (1/mm^2); distance to GT (share: inside GT / outside GT):\n", name.c_str(),
              pred.size());
  const char* names[] = {"<2mm", "2-5mm", "5-10mm", "10-20mm", "20-40mm", ">=40mm"};
  for (int b = 0; b < 6; ++b)
    std::printf("  %-8s %.4f (in %.4f / out %.4f)\n", names[b], (cnt[b][0] + cnt[b][1]) / n, cnt[b][0] / n,
                cnt[b][1] / n);
  std::printf("  samples with z < 4 mm (table level): %.4f of all, %.4f of all are >= 5 mm from GT\n", table / n,
              table_far / n);
  // By the sample's height band (z) for the far ones.
  {
    const double zb[] = {0.004, 0.01, 0.02, 0.05, 0.1, 0.2, 1e9};
    std::size_t zc[7] = {}, zall[7] = {};
    for (const auto& p : pred) {
      int b = 0;
      while (p.z() >= zb[b]) ++b;
      ++zall[b];
    }
    for (const auto& p : far) {
      int b = 0;
      while (p.z() >= zb[b]) ++b;
      ++zc[b];
    }
    std::printf("  far (>=5mm) by height z: ");
    const char* zn[] = {"<4mm", "4-10", "10-20", "20-50", "50-100", "100-200", ">200"};
    for (int b = 0; b < 7; ++b) std::printf("%s %.4f/%.4f  ", zn[b], zc[b] / n, zall[b] / n);
    std::printf("(far share / all share)\n");
  }
  {  // Beyond the figurines' base (r_xy > 0.262 m): no foreground there in the figurines set.
    std::size_t out_all = 0, out_far = 0, zb[4] = {};
    for (std::size_t i = 0; i < pred.size(); ++i) {
      if (std::hypot(pred[i].x(), pred[i].y()) <= 0.262) continue;
      ++out_all;
      if (std::isfinite(sd[i]) && std::abs(sd[i]) < tau) continue;
      ++out_far;
      const double z = pred[i].z();
      ++zb[z < 0.004 ? 0 : z < 0.025 ? 1 : z < 0.08 ? 2 : 3];
    }
    std::printf("  r_xy > 262 mm: %.4f of all, far %.4f (z <4mm %.4f, 4-25 %.4f, 25-80 %.4f, >80 %.4f)\n", out_all / n,
                out_far / n, zb[0] / n, zb[1] / n, zb[2] / n, zb[3] / n);
  }
  // Pictures of where the far samples lie (LFRECON_ANALYZE_PNG=prefix): top view (x, y; 1 px = 1 mm) and an
  // unrolled side view (angle around the z axis, z; 1 px = 1 mm at r = 0.2 m); grey within τ, red: far and
  // outside the ground truth, blue: far and inside; the later-drawn far samples win.
  if (const char* png = std::getenv("LFRECON_ANALYZE_PNG")) {
    const int W = 560, H = 540, SW = 1257, SH = 460;
    cv::Mat top(H, W, CV_8UC3, cv::Scalar(255, 255, 255)), side(SH, SW, CV_8UC3, cv::Scalar(255, 255, 255));
    for (int pass = 0; pass < 2; ++pass)
      for (std::size_t i = 0; i < pred.size(); ++i) {
        const double a = std::isfinite(sd[i]) ? std::abs(sd[i]) : 1;
        const bool isfar = a >= tau;
        if (isfar != (pass == 1)) continue;
        const cv::Vec3b col = !isfar ? cv::Vec3b(170, 170, 170) : (sd[i] > 0 ? cv::Vec3b(0, 0, 230) : cv::Vec3b(230, 0, 0));
        const Eigen::Vector3d& q = pred[i];
        const int tx = static_cast<int>((q.x() + 0.27) * 1000), ty = static_cast<int>((0.27 - q.y()) * 1000);
        if (tx >= 0 && ty >= 0 && tx < W && ty < H) top.at<cv::Vec3b>(ty, tx) = col;
        const double ang = std::atan2(q.y(), q.x());
        const int sx = static_cast<int>((ang + M_PI) / (2 * M_PI) * SW), sy = static_cast<int>((0.455 - q.z()) * 1000);
        if (sx >= 0 && sy >= 0 && sx < SW && sy < SH) side.at<cv::Vec3b>(sy, sx) = col;
      }
    cv::imwrite(std::string(png) + "_top.png", top);
    cv::imwrite(std::string(png) + "_side.png", side);
  }
  const std::vector<Cluster> cl = ClusterPoints(far, far_sd, 0.004);
  std::printf("  %zu clusters of far samples (4 mm grid); largest 20 (share of all samples, centroid, extent mm, mean |d| mm, outside share):\n",
              cl.size());
  std::size_t small = 0;
  for (const Cluster& c : cl)
    if (c.n < 50) small += c.n;
  std::printf("  clusters < 50 samples together: %.4f of all\n", small / n);
  for (std::size_t k = 0; k < std::min<std::size_t>(20, cl.size()); ++k) {
    const Cluster& c = cl[k];
    const Eigen::Vector3d m = c.sum / c.n, e = (c.hi - c.lo) * 1000;
    std::printf("   %.4f  (%.3f %.3f %.3f)  %4.0f x %4.0f x %4.0f  %5.1f  %.2f  e.g. %.4f,%.4f,%.4f\n", c.n / n, m.x(),
                m.y(), m.z(), e.x(), e.y(), e.z(), 1000 * c.dist / c.n, static_cast<double>(c.outside) / c.n, c.rep.x(),
                c.rep.y(), c.rep.z());
  }
  // Connected components of the mesh (triangles sharing vertices): area and the share of it within τ of
  // the ground truth (by triangle centroid), binned by component area.
  {
    std::vector<int> parent(mesh.vertices.size());
    for (std::size_t i = 0; i < parent.size(); ++i) parent[i] = static_cast<int>(i);
    const std::function<int(int)> find = [&](int x) {
      while (parent[x] != x) x = parent[x] = parent[parent[x]];
      return x;
    };
    for (const auto& t : mesh.triangles) {
      const int a = find(t[0]), b = find(t[1]), c = find(t[2]);
      parent[b] = a;
      parent[find(c)] = find(a);
    }
    std::unordered_map<int, std::pair<double, double>> comp;  // root -> (area, area within τ)
    std::vector<double> tri_area(mesh.triangles.size()), tri_d(mesh.triangles.size());
    tbb::parallel_for(std::size_t{0}, mesh.triangles.size(), [&](std::size_t k) {
      const auto& t = mesh.triangles[k];
      const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>(), b = mesh.vertices[t[1]].cast<double>(),
                            c = mesh.vertices[t[2]].cast<double>();
      tri_area[k] = 0.5 * (b - a).cross(c - a).norm();
      tri_d[k] = std::abs(to_gt.Signed((a + b + c) / 3));
    });
    for (std::size_t k = 0; k < mesh.triangles.size(); ++k) {
      auto& e = comp[find(mesh.triangles[k][0])];
      e.first += tri_area[k];
      if (tri_d[k] < tau) e.second += tri_area[k];
    }
    const double lim[] = {1e-4, 1e-3, 1e-2, 1e9};  // m²: 1, 10, 100 cm²
    double area[4] = {}, good[4] = {}, total = 0;
    int num[4] = {};
    for (const auto& [r, e] : comp) {
      int b = 0;
      while (e.first >= lim[b]) ++b;
      area[b] += e.first;
      good[b] += e.second;
      ++num[b];
      total += e.first;
    }
    const char* bn[] = {"<1cm2", "1-10cm2", "10-100cm2", ">=100cm2"};
    std::printf("  mesh components by area: ");
    for (int b = 0; b < 4; ++b)
      std::printf("%s: %d, %.4f of area, P %.3f;  ", bn[b], num[b], area[b] / total, area[b] > 0 ? good[b] / area[b] : 0);
    std::printf("\n");
  }
  // Recall side: GT samples missed, by the GT normal's z.
  const SurfaceDistance to_pred(mesh, 0.01, &volume);
  const std::vector<Eigen::Vector3d> gs = SampleSurface(gt, 0.001, 2);
  const std::vector<double> gd = to_pred.Distances(gs);
  const NearestTriangle gtn(gt, 0.005, 1);
  std::size_t down = 0, down_miss = 0, other = 0, other_miss = 0;
  std::vector<Eigen::Vector3d> missed;
  std::vector<double> missed_d;
  for (std::size_t i = 0; i < gs.size(); ++i) {
    Eigen::Vector3d nn;
    gtn.Signed(gs[i], &nn);
    const bool d = nn.z() < -0.5;
    const bool miss = !(gd[i] <= tau);
    (d ? down : other)++;
    if (miss) (d ? down_miss : other_miss)++;
    if (miss && !d) {
      missed.push_back(gs[i]);
      missed_d.push_back(1);
    }
  }
  std::printf("  GT: %zu samples; facing down (n.z < -0.5): %.4f, missed %.4f; others %.4f, missed %.4f (recall on them %.4f)\n",
              gs.size(), down / (double)gs.size(), down_miss / (double)gs.size(), other / (double)gs.size(),
              other_miss / (double)gs.size(), 1 - other_miss / (double)std::max<std::size_t>(1, other));
  const std::vector<Cluster> mc = ClusterPoints(missed, missed_d, 0.004);
  std::printf("  missed non-down GT clusters, largest 10 (share of GT samples, centroid, extent mm):\n");
  for (std::size_t k = 0; k < std::min<std::size_t>(10, mc.size()); ++k) {
    const Cluster& c = mc[k];
    const Eigen::Vector3d m = c.sum / c.n, e = (c.hi - c.lo) * 1000;
    std::printf("   %.4f  (%.3f %.3f %.3f)  %4.0f x %4.0f x %4.0f\n", c.n / (double)gs.size(), m.x(), m.y(), m.z(), e.x(),
                e.y(), e.z());
  }
  if (thin) {
    const std::vector<Eigen::Vector3d> ts = SampleSurface(*thin, 0.001, 3);
    const std::vector<double> td = to_pred.Distances(ts);
    std::vector<Eigen::Vector3d> tm;
    std::vector<double> tmd;
    for (std::size_t i = 0; i < ts.size(); ++i)
      if (!(td[i] <= tau)) {
        tm.push_back(ts[i]);
        tmd.push_back(1);
      }
    const std::vector<Cluster> tc = ClusterPoints(tm, tmd, 0.004);
    std::printf("  thin: %zu samples, missed %.4f; largest missed clusters (share of thin samples, centroid, extent mm):\n",
                ts.size(), tm.size() / (double)ts.size());
    for (std::size_t k = 0; k < std::min<std::size_t>(12, tc.size()); ++k) {
      const Cluster& c = tc[k];
      const Eigen::Vector3d m = c.sum / c.n, e = (c.hi - c.lo) * 1000;
      std::printf("   %.4f  (%.3f %.3f %.3f)  %4.0f x %4.0f x %4.0f\n", c.n / (double)ts.size(), m.x(), m.y(), m.z(),
                  e.x(), e.y(), e.z());
    }
  }
  std::fflush(stdout);
}

}  // namespace


int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr,
                 "usage: %s DATASET DEPTH_OUT|- [--sigma-s a,b,...] [--voxel-mm MM] [--prune-every N]\n"
                 "  [--activation-min-confidence C] [--threshold H] [--band B] [--free-space-margin M] [--min-views N]\n"
                 "  [--refine cp,p,c (carve+Poisson, Poisson, carve+marching cubes)] [--carving-views N] [--consistency T]\n"
                 "  [--min-component-cm2 a,b,...] [--analyze 0|1]\n"
                 "  [--geo-consistency O1/O2/...,MIN,TOL [--geo-radius R] [--geo-reproj PX] [--geo-soft 1]]\n"
                 "  [--keep-mesh DIR] [--mesh FILE.ply (analyse this mesh only; DEPTH_OUT may be -)]\n"
                 "  [--score 0 (time fusion only: no scoring)] [--max-views N] [--threads N]\n",
                 argv[0]);
    return 2;
  }
  const fs::path dataset_dir = argv[1], depth_dir = argv[2];
  std::vector<double> sigmas = {0.15};
  double voxel_mm = 0;
  int prune_every = 0;
  fs::path keep_dir, mesh_file;
  double min_conf = 0.01, band = -1, margin = -1e9, bg_floor = 0;
  std::vector<double> thresholds = {-1};
  std::vector<double> clamps = {FusionOptions{}.probability_clamp};
  int carving_views = 24;
  std::vector<int> min_views_list = {1};
  bool refine = false, analyze = false, score = true;
  int max_views = 0, threads = 0;
  double consistency = -1;
  double oracle_clean_mm = -1;
  double measured_floor = 0;
  double bg_gate_px = 0;
  fs::path measured_dir;  // < 0: off; 0: GT views only, uncleaned; > 0: also drop |d - gt| > MM
  std::vector<std::string> variants;
  std::vector<double> min_comp_cm2;
  std::vector<Eigen::Vector3d> probes;
  int cons_views = 0;
  double cons_min = 0.4;
  std::vector<int> geo_offsets;  // --geo-consistency: map-index offsets of the checking views
  int geo_min_agree = 0;
  double geo_tol = 0.01, geo_reproj_px = 0;
  int geo_radius = 0;
  bool geo_soft = false;
  fs::path geo_spare_dir;  // filtered (§3.2) maps: pixels with a depth of their own there are not checked
  int cons_radius = DenseConsistencyOptions{}.patch_radius_px;
  for (int a = 3; a + 1 < argc; a += 2) {
    const std::string k = argv[a], v = argv[a + 1];
    if (k == "--sigma-s") {
      sigmas.clear();
      std::stringstream ss(v);
      std::string item;
      while (std::getline(ss, item, ',')) sigmas.push_back(std::atof(item.c_str()));
    } else if (k == "--voxel-mm") {
      voxel_mm = std::atof(v.c_str());
    } else if (k == "--prune-every") {
      prune_every = std::atoi(v.c_str());
    } else if (k == "--activation-min-confidence") {
      min_conf = std::atof(v.c_str());
    } else if (k == "--threshold") {  // a list: each is meshed from the same fusion
      thresholds.clear();
      std::stringstream ss(v);
      std::string item;
      while (std::getline(ss, item, ',')) thresholds.push_back(std::atof(item.c_str()));
    } else if (k == "--probability-clamp") {  // a list: one fusion each
      clamps.clear();
      std::stringstream ss(v);
      std::string item;
      while (std::getline(ss, item, ',')) clamps.push_back(std::atof(item.c_str()));
    } else if (k == "--measured-bg-floor") {  // F,DIR: floor only where DIR's (filtered) maps measured background
      const auto comma = v.find(',');
      measured_floor = std::atof(v.substr(0, comma).c_str());
      if (comma != std::string::npos) measured_dir = v.substr(comma + 1);
    } else if (k == "--bg-floor-gate") {  // the floor only at least PX pixels from any foreground depth
      bg_gate_px = std::atof(v.c_str());
    } else if (k == "--bg-confidence-floor") {
      bg_floor = std::atof(v.c_str());
    } else if (k == "--band") {
      band = std::atof(v.c_str());
    } else if (k == "--free-space-margin") {
      margin = std::atof(v.c_str());
    } else if (k == "--min-views") {  // a list: each is meshed from the same fusion
      min_views_list.clear();
      std::stringstream ss(v);
      std::string item;
      while (std::getline(ss, item, ',')) min_views_list.push_back(std::atoi(item.c_str()));
    } else if (k == "--refine") {  // variants: cp (carve + Poisson), p (Poisson only), c (carve, marching cubes)
      std::stringstream ss(v);
      std::string item;
      while (std::getline(ss, item, ',')) variants.push_back(item);
      refine = !variants.empty() && variants[0] != "0";
      if (v == "1") variants = {"cp"};
    } else if (k == "--carving-views") {
      carving_views = std::atoi(v.c_str());
    } else if (k == "--consistency") {
      consistency = std::atof(v.c_str());
    } else if (k == "--min-component-cm2") {
      std::stringstream ss(v);
      std::string item;
      while (std::getline(ss, item, ',')) min_comp_cm2.push_back(std::atof(item.c_str()));
    } else if (k == "--probe") {  // x,y,z;x,y,z: every view's evidence about these points
      std::stringstream ss(v);
      std::string item;
      while (std::getline(ss, item, ';')) {
        Eigen::Vector3d q;
        if (std::sscanf(item.c_str(), "%lf,%lf,%lf", &q.x(), &q.y(), &q.z()) == 3) probes.push_back(q);
      }
    } else if (k == "--dense-consistency") {  // views,rho_min: CheckDenseConsistency on the loaded maps
      std::sscanf(v.c_str(), "%d,%lf,%d", &cons_views, &cons_min, &cons_radius);
    } else if (k == "--geo-consistency") {  // O1/O2/..,MIN,TOL: multi-view depth agreement (diagnosis)
      const auto c1 = v.find(',');
      std::stringstream ss(v.substr(0, c1));
      std::string item;
      while (std::getline(ss, item, '/')) geo_offsets.push_back(std::atoi(item.c_str()));
      if (c1 != std::string::npos) std::sscanf(v.c_str() + c1 + 1, "%d,%lf", &geo_min_agree, &geo_tol);
    } else if (k == "--geo-radius") {  // look for agreement within R pixels of the projection
      geo_radius = std::atoi(v.c_str());
    } else if (k == "--geo-reproj") {  // agreement = back-projection within PX pixels (COLMAP-like), not TOL
      geo_reproj_px = std::atof(v.c_str());
    } else if (k == "--geo-spare-own") {  // DIR of `lfrecon depth --stage filtered`: own depths are not checked
      geo_spare_dir = v;
    } else if (k == "--geo-soft") {  // 1: scale the confidence by agreeing / MIN instead of dropping the depth
      geo_soft = std::atoi(v.c_str()) != 0;
    } else if (k == "--oracle-clean") {  // diagnosis: keep only views with GT depth; drop depths off it by > MM
      oracle_clean_mm = std::atof(v.c_str());
    } else if (k == "--score") {
      score = std::atoi(v.c_str()) != 0;
    } else if (k == "--max-views") {
      max_views = std::atoi(v.c_str());
    } else if (k == "--threads") {
      threads = std::atoi(v.c_str());
    } else if (k == "--analyze") {
      analyze = std::atoi(v.c_str()) != 0;
    } else if (k == "--keep-mesh") {
      keep_dir = v;
    } else if (k == "--mesh") {
      mesh_file = v;
    } else {
      std::fprintf(stderr, "unknown option %s\n", k.c_str());
      return 2;
    }
  }
  std::unique_ptr<tbb::global_control> thread_limit;
  if (threads > 0)
    thread_limit = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, threads);
  DatasetOptions dopt;
  dopt.dataset_dir = dataset_dir;
  const Dataset ds = Dataset::Open(dopt);
  const auto gt_path = ds.GroundTruthMeshPath(false);
  if (!gt_path) {
    std::fprintf(stderr, "%s has no ground-truth mesh\n", dataset_dir.c_str());
    return 1;
  }
  const TriangleMesh gt = ReadPly(*gt_path);
  const auto thin_path = ds.GroundTruthMeshPath(true);
  TriangleMesh thin;
  if (thin_path) thin = ReadPly(*thin_path);
  MeshMetricsOptions mo;
  mo.thresholds = {0.002, 0.005, 0.010};
  mo.volume = ds.bbox();
  const auto score_line = [&](const TriangleMesh& mesh) {
    const MeshMetrics m = EvaluateMesh(mesh, gt, thin_path ? &thin : nullptr, mo);
    char buf[256];
    std::snprintf(buf, sizeof(buf), "%.3f  %.3f  %.3f  %.3f  %.3f  %.3f  %.3f  %.3f", m.scores[0].fscore,
                  m.scores[1].fscore, m.scores[2].fscore, m.scores[1].precision, m.scores[1].recall,
                  m.scores[0].thin_recall, m.scores[1].thin_recall, m.scores[2].thin_recall);
    return std::string(buf);
  };
  if (!mesh_file.empty()) {
    const TriangleMesh mesh = ReadPly(mesh_file);
    std::printf("F@2    F@5    F@10   P@5    R@5    thin@2 thin@5 thin@10\n%s\n", score_line(mesh).c_str());
    AnalyzeMesh(mesh_file.filename().string(), mesh, gt, thin_path ? &thin : nullptr, ds.bbox());
    return 0;
  }
  // Maps present on disk, by image stem.
  std::vector<int> ids;
  std::vector<DepthMap> maps;
  for (int i = 0; i < ds.NumViews(); ++i) {
    const std::string stem = fs::path(ds.views()[i].name).stem().string();
    const fs::path d = depth_dir / "depth" / (stem + ".pfm"), c = depth_dir / "confidence" / (stem + ".pfm");
    if (!fs::exists(d)) continue;
    DepthMap m;
    m.depth = ReadPfm(d);
    if (fs::exists(c)) m.confidence = ReadPfm(c);
    ids.push_back(i);
    maps.push_back(std::move(m));
  }
  if (max_views > 0 && static_cast<int>(maps.size()) > max_views) {  // every k-th map
    const std::size_t k = (maps.size() + max_views - 1) / max_views;
    std::vector<int> kept_ids;
    std::vector<DepthMap> kept;
    for (std::size_t i = 0; i < maps.size(); i += k) {
      kept_ids.push_back(ids[i]);
      kept.push_back(std::move(maps[i]));
    }
    ids = std::move(kept_ids);
    maps = std::move(kept);
  }
  std::printf("%zu depth maps from %s\n", maps.size(), depth_dir.c_str());
  if (oracle_clean_mm >= 0) {
    // What the fusion would give from depth maps without their errors: only
    // views with ground-truth depth are kept; with MM > 0 every depth more than
    // MM from the truth there (or where the truth has no surface) is dropped, of the depths inside V
    // (foreground; background depths keep giving free space).
    std::vector<int> kept_ids;
    std::vector<DepthMap> kept;
    long long dropped_front = 0, dropped_behind = 0, total = 0;
    for (std::size_t k = 0; k < maps.size(); ++k) {
      const auto gt_depth = ds.GroundTruthDepthPath(ids[k]);
      if (!gt_depth) continue;
      if (oracle_clean_mm > 0) {
        const cv::Mat g = ReadDepthMap(*gt_depth);
        for (int r = 0; r < maps[k].depth.rows; ++r)
          for (int c = 0; c < maps[k].depth.cols; ++c) {
            float& d = maps[k].depth.at<float>(r, c);
            if (!(d > 0)) continue;
            if (!ds.bbox().Contains(ds.View(ids[k]).Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), d))) continue;
            ++total;
            const double t = g.at<float>(r, c);
            const bool off = !(t > 0) || std::abs(d - t) > oracle_clean_mm / 1000;
            if (!off) continue;
            (t > 0 && d > t ? dropped_behind : dropped_front)++;
            d = 0;
            if (!maps[k].confidence.empty()) maps[k].confidence.at<float>(r, c) = 0;
          }
      }
      kept_ids.push_back(ids[k]);
      kept.push_back(std::move(maps[k]));
    }
    ids = std::move(kept_ids);
    maps = std::move(kept);
    std::printf("oracle: %zu views with ground-truth depth; %.4f of depths dropped in front of the truth, %.4f behind\n",
                maps.size(), double(dropped_front) / std::max(1LL, total), double(dropped_behind) / std::max(1LL, total));
  }
  if (maps.empty()) return 1;
  if (!geo_offsets.empty()) {
    // Multi-view geometric consistency: the plain check (no radius, reprojection
    // or soft weights) is the pipeline's ApplyGeometricConsistency, with
    // offsets in map order; the variants are diagnoses. A
    // foreground depth (inside V) of map k is kept when at least MIN of the
    // maps k +- o (o in the offsets, in map order) see the same point: their
    // depth within R pixels of its projection is within TOL (relative) of the
    // point's depth in them, or (--geo-reproj) back-projects into map k within
    // PX pixels. Offsets are map indices: choose them for the set's spacing.
    Timer gt_timer;
    std::vector<PinholeView> vs;
    for (int id : ids) vs.push_back(ds.View(id));
    std::vector<cv::Mat> out(maps.size());
    long long fg = 0, dropped = 0;
    long long spared = 0;
    std::mutex mu;  // guards fg, dropped, spared
    tbb::parallel_for(std::size_t{0}, maps.size(), [&](std::size_t k) {
      out[k] = maps[k].depth.clone();
      cv::Mat own;
      if (!geo_spare_dir.empty()) {
        const fs::path f = geo_spare_dir / "depth" / (fs::path(ds.views()[ids[k]].name).stem().string() + ".pfm");
        if (fs::exists(f)) own = ReadPfm(f);
      }
      long long l_spared = 0;
      long long l_fg = 0, l_drop = 0;
      if (geo_radius == 0 && geo_reproj_px <= 0 && !geo_soft) {
        // The plain check is the pipeline's (ApplyGeometricConsistency), with map-index offsets.
        GeometricConsistencyOptions gc;
        gc.offsets = geo_offsets;
        gc.min_agree = geo_min_agree;
        gc.min_agree_fraction = 0;  // MIN is absolute here
        gc.depth_tolerance = geo_tol;
        gc.own_tolerance = geo_tol;
        std::vector<NeighbourDepth> nbs;
        for (int o : geo_offsets)
          for (int sgn : {-1, 1}) {
            const long j = static_cast<long>(k) + sgn * o;
            if (j >= 0 && j < static_cast<long>(maps.size())) nbs.push_back({&vs[j], &maps[j].depth});
          }
        DepthMap checked;
        checked.depth = out[k];  // shares out[k]'s pixels: the check writes into it
        checked.confidence = cv::Mat::zeros(out[k].size(), CV_32F);
        checked.label = cv::Mat::zeros(out[k].size(), CV_8U);
        DepthMap filtered;
        filtered.depth = own;
        const cv::Mat own_mask = own.empty() ? cv::Mat() : OwnDepthMask(maps[k], filtered, geo_tol);
        const GeometricConsistencyStats gs = ApplyGeometricConsistency(vs[k], own_mask, nbs, ds.bbox(), gc, &checked);
        std::lock_guard<std::mutex> lock(mu);
        fg += gs.foreground;
        dropped += gs.dropped;
        spared += gs.own;
        return;
      }
      for (int r = 0; r < maps[k].depth.rows; ++r)
        for (int c = 0; c < maps[k].depth.cols; ++c) {
          const float d = maps[k].depth.at<float>(r, c);
          if (!(d > 0)) continue;
          const Eigen::Vector3d X = vs[k].Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), d);
          if (!ds.bbox().Contains(X)) continue;
          ++l_fg;
          if (!own.empty()) {
            const float o = own.at<float>(r, c);
            if (o > 0 && std::abs(o - d) < geo_tol * d) {
              ++l_spared;
              continue;
            }
          }
          int agree = 0;
          for (int o : geo_offsets)
            for (int sgn : {-1, 1}) {
              const long j = static_cast<long>(k) + sgn * o;
              if (j < 0 || j >= static_cast<long>(maps.size())) continue;
              Eigen::Vector2d px;
              const double z = vs[j].Project(X, &px);
              if (!(z > 0) || !vs[j].InImage(px)) continue;
              const int pr = static_cast<int>(px.y()), pc = static_cast<int>(px.x());
              bool ok = false;
              for (int dr = -geo_radius; dr <= geo_radius && !ok; ++dr)
                for (int dc = -geo_radius; dc <= geo_radius && !ok; ++dc) {
                  const int rr = pr + dr, cc = pc + dc;
                  if (rr < 0 || cc < 0 || rr >= maps[j].depth.rows || cc >= maps[j].depth.cols) continue;
                  const float dd = maps[j].depth.at<float>(rr, cc);
                  if (geo_reproj_px > 0) {  // COLMAP-like: back into view k within PX
                    if (!(dd > 0)) continue;
                    const Eigen::Vector3d Xj = vs[j].Unproject(Eigen::Vector2d(cc + 0.5, rr + 0.5), dd);
                    Eigen::Vector2d back;
                    const double zb = vs[k].Project(Xj, &back);
                    ok = zb > 0 && (back - Eigen::Vector2d(c + 0.5, r + 0.5)).norm() <= geo_reproj_px;
                  } else {
                    ok = dd > 0 && std::abs(dd - z) < geo_tol * z;
                  }
                }
              if (ok) ++agree;
            }
          if (agree >= geo_min_agree) continue;
          ++l_drop;
          if (geo_soft && !maps[k].confidence.empty())
            maps[k].confidence.at<float>(r, c) *= float(agree) / geo_min_agree;
          else
            out[k].at<float>(r, c) = 0;
        }
      std::lock_guard<std::mutex> lock(mu);
      fg += l_fg;
      dropped += l_drop;
      spared += l_spared;
    });
    for (std::size_t k = 0; k < maps.size(); ++k) {
      if (!maps[k].confidence.empty()) maps[k].confidence.setTo(0, out[k] <= 0);
      maps[k].depth = out[k];
    }
    std::printf("geometric consistency (min %d, tol %.3f, radius %d, reproj %.1f px%s): %.4f of %lld foreground depths "
                "%s, %.1f s\n", geo_min_agree, geo_tol, geo_radius, geo_reproj_px, geo_soft ? ", soft" : "",
                double(dropped) / std::max(1LL, fg), fg, geo_soft ? "down-weighted" : "dropped", gt_timer.Seconds());
    if (!geo_spare_dir.empty())
      std::printf("  %.4f spared: a filtered depth of their own within the tolerance\n", double(spared) / std::max(1LL, fg));
  }
  if (cons_views > 0) {
    // The dense maps' foreground depths checked against the frames (as
    // DepthPropagator does after its filter, for maps written without it).
    Timer ct;
    DenseConsistencyOptions co;
    co.views = cons_views;
    co.rho_min = cons_min;
    co.patch_radius_px = cons_radius;
    auto frames = ds.OpenFrames();
    std::vector<PinholeView> all;
    for (int i = 0; i < ds.NumViews(); ++i) all.push_back(ds.View(i));
    std::vector<const PinholeView*> all_ptr;
    for (const PinholeView& v : all) all_ptr.push_back(&v);
    const auto load = [&](int id) {
      ViewImage v;
      v.view = all[static_cast<std::size_t>(id)];
      v.image = frames->Read(id).image;
      cv::GaussianBlur(v.image, v.smoothed, cv::Size(0, 0), 0.65);
      return v;
    };
    long long before = 0, after = 0;
    for (std::size_t k = 0; k < maps.size(); ++k) {
      const ViewImage ref = load(ids[k]);
      DepthMap labelled = DepthPropagator::LabelFromVolume(ref.view, maps[k], ds.bbox());
      std::vector<ViewImage> nbs;
      for (int j : DenseConsistencyAccumulator(co).SelectNeighbors(ref.view, all_ptr)) nbs.push_back(load(j));
      std::vector<const ViewImage*> nb_ptr;
      for (const ViewImage& v : nbs) nb_ptr.push_back(&v);
      before += labelled.CountValid();
      CheckDenseConsistency(ref, nb_ptr, co, &labelled);
      after += labelled.CountValid();
      maps[k].depth = labelled.depth;
      maps[k].confidence = labelled.confidence;
    }
    std::printf("dense consistency (%d views, rho_min %.2f, patch radius %d px): %.3f of the depths removed, %.1f s\n",
                cons_views, cons_min, cons_radius, 1.0 - double(after) / std::max(1LL, before), ct.Seconds());
  }
  if (measured_floor > 0) {
    // Background depths of the dense maps get at least this confidence where
    // the filtered (sparse) map of the same view measured a background depth
    // itself (not propagated).
    std::size_t raised = 0, measured = 0;
    for (std::size_t k = 0; k < maps.size(); ++k) {
      const PinholeView view = ds.View(ids[k]);
      const fs::path f = measured_dir / "depth" / (fs::path(ds.views()[ids[k]].name).stem().string() + ".pfm");
      if (!fs::exists(f) || maps[k].confidence.empty()) continue;
      const cv::Mat sparse = ReadPfm(f);
      for (int r = 0; r < maps[k].depth.rows; ++r)
        for (int c = 0; c < maps[k].depth.cols; ++c) {
          const float ds_ = sparse.at<float>(r, c);
          if (!(ds_ > 0) || ds.bbox().Contains(view.Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), ds_))) continue;
          ++measured;
          const float d = maps[k].depth.at<float>(r, c);
          float& cf = maps[k].confidence.at<float>(r, c);
          if (d <= 0 || cf >= measured_floor) continue;
          if (ds.bbox().Contains(view.Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), d))) continue;
          cf = static_cast<float>(measured_floor);
          ++raised;
        }
    }
    std::printf("measured background floor %.3f: %zu measured background pixels, %zu raised\n", measured_floor,
                measured, raised);
  }
  if (bg_floor > 0) {  // depths beyond V (background) get at least this confidence: PipelineOptions::background_floor without its sparse gate
    std::size_t raised = 0;
    for (std::size_t k = 0; k < maps.size(); ++k) {
      if (maps[k].confidence.empty()) continue;
      const cv::Mat before = maps[k].confidence;
      maps[k] = WithGatedBackgroundFloor(maps[k], ds.View(ids[k]), ds.bbox(), bg_floor, bg_gate_px);
      raised += static_cast<std::size_t>(cv::countNonZero(maps[k].confidence != before));
    }
    std::printf("background confidence floor %.3f: %zu pixels raised\n", bg_floor, raised);
  }
  if (!probes.empty()) {
    FusionOptions fo;
    fo.volume = ds.bbox();
    fo.voxel_size = voxel_mm > 0 ? voxel_mm / 1000 : ds.bbox().Extent().maxCoeff() / 256;
    fo.sigma_s = sigmas[0];
    for (const Eigen::Vector3d& q : probes) {
      int pos = 0, neg = 0, none = 0;
      double sum = 0;
      std::printf("probe (%.4f %.4f %.4f): view: d_v, depth, conf, c, logP\n", q.x(), q.y(), q.z());
      for (std::size_t k = 0; k < maps.size(); ++k) {
        const PinholeView view = ds.View(ids[k]);
        const CompactDepthView cv(view, maps[k], ds.bbox());
        const SurfaceEvidence ev(cv, fo);
        float lp;
        double c;
        const Eigen::Vector3d xc = view.R * q + view.t;
        if (!ev.LogProbability(q, &lp, &c)) {
          ++none;
          continue;
        }
        const Eigen::Vector3d h = view.K * xc;
        const int u = static_cast<int>(h.x() / h.z()), r = static_cast<int>(h.y() / h.z());
        const float dd = maps[k].depth.at<float>(r, u);
        const float cc = maps[k].confidence.empty() ? 1.f : maps[k].confidence.at<float>(r, u);
        sum += lp;
        (c > 0 ? pos : neg)++;
        std::printf("  %3d: %.4f %.4f %.3f %+.3f %.2f\n", ids[k], xc.z(), dd, cc, c, lp);
      }
      std::printf("  => %d positive, %d negative, %d silent; H = %.3f\n", pos, neg, none,
                  pos + neg > 0 ? std::exp(sum / (pos + neg)) : 0.0);
    }
    return 0;
  }
  // Frames for carving, evenly spread over the views with maps (as the pipeline keeps them).
  std::vector<ColorView> carve_views;
  if (refine && carving_views > 0) {
    auto frames = ds.OpenFrames();
    const int kc = std::min<int>(carving_views, static_cast<int>(ids.size()));
    for (int c = 0; c < kc; ++c) {
      const int id = ids[static_cast<std::size_t>(c) * ids.size() / kc];
      const Frame f = frames->Read(id);
      carve_views.push_back({ds.View(id), f.image, cv::Mat()});
    }
  }
  const double voxel = voxel_mm > 0 ? voxel_mm / 1000 : ds.bbox().Extent().maxCoeff() / 256;
  std::printf("voxel %.3f mm, prune every %d, activation min confidence %.3f\n", voxel * 1000, prune_every,
              min_conf);
  std::printf("sigma_s  mesh     F@2    F@5    F@10   P@5    R@5    thin@2 thin@5 thin@10  triangles  active  fuse_s\n");
  for (double s : sigmas)
  for (double clamp : clamps) {
    std::printf("probability clamp %g\n", clamp);
    FusionOptions fo;
    fo.probability_clamp = clamp;
    fo.volume = ds.bbox();
    fo.voxel_size = voxel;
    fo.sigma_s = s;
    fo.prune_every = prune_every;
    fo.activation_min_confidence = min_conf;
    if (band > 0) fo.band = band;
    if (margin > -1e8) fo.free_space_margin = margin;
    ProbabilisticFusion fusion(fo);
    Timer t;
    for (std::size_t k = 0; k < maps.size(); ++k) fusion.Integrate(ds.View(ids[k]), maps[k], ids[k]);
    const double fuse_s = t.Seconds();
    if (!score) {  // the cost of fusion alone
      const FusionStats st = fusion.Stats();
      std::printf("fusion of %zu views: %.2f s (activate %.2f, back-fill %.2f, update %.2f), %zu active voxels\n",
                  maps.size(), fuse_s, st.activate_s, st.backfill_s, st.update_s, st.active_voxels);
    }
    for (double threshold : thresholds)
    for (int min_views : min_views_list) {
      MeshingOptions meshing;
      meshing.threshold = threshold;
      std::printf("threshold %.2f, min views %d\n", threshold < 0 ? fo.surface_threshold : threshold, min_views);
      meshing.min_views = min_views;
      Timer tm;
      const TriangleMesh mesh = fusion.ExtractMesh(meshing);
      if (!score) {
        std::printf("meshing: %.2f s, %zu triangles\n", tm.Seconds(), mesh.triangles.size());
        if (!keep_dir.empty()) {
          fs::create_directories(keep_dir);
          WritePly(mesh, keep_dir / "fused.ply");
        }
        continue;
      }
      std::printf("%-7.3f  fused    %s   %9zu  %7zu  %6.1f\n", s, score_line(mesh).c_str(), mesh.triangles.size(),
                  fusion.Stats().active_voxels, fuse_s);
      std::fflush(stdout);
      char name[64];
      std::snprintf(name, sizeof(name), "sigma_%.3f", s);
      if (!keep_dir.empty()) {
        fs::create_directories(keep_dir);
        WritePly(mesh, keep_dir / (std::string("fused_") + name + ".ply"));
      }
      if (analyze) AnalyzeMesh(std::string("fused ") + name, mesh, gt, thin_path ? &thin : nullptr, ds.bbox());
      for (double a : min_comp_cm2) {
        ComponentFilterStats cs;
        const TriangleMesh f = RemoveSmallComponents(mesh, a * 1e-4, &cs);
        std::printf("%-7.3f  >=%-5gcm2 %s   %9zu  removed %zu of %zu components, %.1f cm2\n", s, a, score_line(f).c_str(),
                    f.triangles.size(), cs.components_removed, cs.components, cs.area_removed * 1e4);
        std::fflush(stdout);
      }
      for (const std::string& variant : refine ? variants : std::vector<std::string>{}) {
        RefineOptions ro;
        // "c" / "cp" / "p", optionally followed by carving settings: ":r6" rounds (and region depth),
        // ":w0" carve next to the unobserved inside, ":t0.9" consistency threshold, ":m3" min views,
        // ":s0" sample at voxel centres, ":c0.5" views below this cosine to the normal get no weight, e.g. "c:r6:w0".
        const std::string head = variant.substr(0, variant.find(':'));
        ro.carve = head.find('c') != std::string::npos;
        ro.use_poisson = head.find('p') != std::string::npos;
        if (consistency > 0) ro.carving.consistency_threshold = consistency;
        for (std::size_t at = variant.find(':'); at != std::string::npos; at = variant.find(':', at + 1)) {
          const char key = variant[at + 1];
          const double val = std::atof(variant.c_str() + at + 2);
          if (key == 'r') ro.carving.max_rounds = ro.carving.region_depth = static_cast<int>(val);
          if (key == 'w') ro.carving.keep_inner_wall = val != 0;
          if (key == 't') ro.carving.consistency_threshold = val;
          if (key == 'm') ro.carving.min_views = static_cast<int>(val);
          if (key == 's') ro.carving.sample_at_surface = val != 0;
          if (key == 'c') ro.carving.min_cos = val;
        }
        Timer tr;
        const RefineResult rr = RefineFusedSurface(fusion, carve_views, ro, meshing);
        std::printf("%-7.3f  ref %-4s %s   %9zu  carved %zu  %6.1f s\n", s, variant.c_str(), score_line(rr.mesh).c_str(),
                    rr.mesh.triangles.size(), rr.stats.carved, tr.Seconds());
        std::fflush(stdout);
        if (!keep_dir.empty()) WritePly(rr.mesh, keep_dir / ("refined_" + variant + "_" + name + ".ply"));
        if (analyze) AnalyzeMesh(std::string("refined ") + name, rr.mesh, gt, thin_path ? &thin : nullptr, ds.bbox());
      }
    }
  }
  return 0;
}
