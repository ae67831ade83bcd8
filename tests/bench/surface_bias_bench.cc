// Benchmark (not a test): is a reconstructed surface offset from the ground truth, and by how much?
//   surface_bias_bench DATASET MESH.ply [--max-mm D]
// Samples MESH every 1 mm (inside the dataset's V) and signs each sample's distance to the nearest
// ground-truth triangle by that triangle's normal (positive: outside the object, as gt_mesh.ply's
// triangles face outward). Prints the signed-distance quantiles of the samples within D mm
// (default 5) and a histogram in 0.25 mm bins, then the same from ground truth to MESH (positive:
// the ground truth lies outside the reconstruction). A surface grown or shrunk by a constant shows
// as a shifted median; a noisy but unbiased one as wide quantiles around 0.
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <string>
#include <unordered_map>
#include <vector>

#include "eval/mesh_metrics.h"
#include "io/dataset.h"
#include "io/ply.h"

using namespace lfrecon;

namespace {

Eigen::Vector3d ClosestOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                  const Eigen::Vector3d& c) {
  // Ericson, Real-Time Collision Detection 5.1.5.
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + d1 / (d1 - d3) * ab;
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + d2 / (d2 - d6) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b);
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

// Signed distance to a triangle soup within `max_distance` (NaN beyond), hash grid of that cell size.
class SignedSurfaceDistance {
 public:
  SignedSurfaceDistance(const TriangleMesh& mesh, double max_distance) : cell_(max_distance) {
    for (const Eigen::Vector3i& t : mesh.triangles) {
      const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>(), b = mesh.vertices[t[1]].cast<double>(),
                            c = mesh.vertices[t[2]].cast<double>();
      const Eigen::Vector3d n = (b - a).cross(c - a);
      if (n.norm() < 1e-18) continue;
      const int id = static_cast<int>(a_.size());
      a_.push_back(a), b_.push_back(b), c_.push_back(c), n_.push_back(n.normalized());
      const Eigen::Vector3d lo = a.cwiseMin(b).cwiseMin(c) / cell_, hi = a.cwiseMax(b).cwiseMax(c) / cell_;
      for (int i = (int)std::floor(lo.x()); i <= (int)std::floor(hi.x()); ++i)
        for (int j = (int)std::floor(lo.y()); j <= (int)std::floor(hi.y()); ++j)
          for (int k = (int)std::floor(lo.z()); k <= (int)std::floor(hi.z()); ++k) cells_[Key(i, j, k)].push_back(id);
    }
  }
  double Signed(const Eigen::Vector3d& p) const {
    const int ci = (int)std::floor(p.x() / cell_), cj = (int)std::floor(p.y() / cell_),
              ck = (int)std::floor(p.z() / cell_);
    double best = cell_ * cell_;
    int best_id = -1;
    Eigen::Vector3d best_q;
    for (int di = -1; di <= 1; ++di)
      for (int dj = -1; dj <= 1; ++dj)
        for (int dk = -1; dk <= 1; ++dk) {
          const auto it = cells_.find(Key(ci + di, cj + dj, ck + dk));
          if (it == cells_.end()) continue;
          for (int id : it->second) {
            const Eigen::Vector3d q = ClosestOnTriangle(p, a_[id], b_[id], c_[id]);
            const double d2 = (p - q).squaredNorm();
            if (d2 < best) best = d2, best_id = id, best_q = q;
          }
        }
    if (best_id < 0) return std::numeric_limits<double>::quiet_NaN();
    const double d = std::sqrt(best);
    return (p - best_q).dot(n_[best_id]) >= 0 ? d : -d;
  }

 private:
  static std::uint64_t Key(int i, int j, int k) {
    const auto u = [](int v) { return static_cast<std::uint64_t>(static_cast<std::uint32_t>(v + (1 << 20))) & 0x1fffff; };
    return (u(i) << 42) | (u(j) << 21) | u(k);
  }
  double cell_;
  std::vector<Eigen::Vector3d> a_, b_, c_, n_;
  std::unordered_map<std::uint64_t, std::vector<int>> cells_;
};

void Report(const char* label, const std::vector<Eigen::Vector3d>& samples, const SignedSurfaceDistance& to,
            double max_distance) {
  std::vector<double> s;
  std::size_t far = 0;
  for (const auto& p : samples) {
    const double d = to.Signed(p);
    if (std::isnan(d) || std::abs(d) > max_distance) ++far;
    else s.push_back(d);
  }
  std::sort(s.begin(), s.end());
  const auto q = [&](double f) { return s.empty() ? 0.0 : s[std::min(s.size() - 1, (std::size_t)(f * s.size()))]; };
  double mean = 0;
  for (double d : s) mean += d;
  mean /= std::max<std::size_t>(1, s.size());
  std::size_t within2 = 0, pos = 0;
  for (double d : s) within2 += std::abs(d) <= 0.002, pos += d > 0;
  std::printf("%s: %zu samples, %zu beyond %.1f mm; within: mean %+.3f mm, outside share %.3f\n", label,
              samples.size(), far, max_distance * 1e3, mean * 1e3, (double)pos / std::max<std::size_t>(1, s.size()));
  std::printf("  quantiles (mm) 5%% %+.2f 10%% %+.2f 25%% %+.2f 50%% %+.2f 75%% %+.2f 90%% %+.2f 95%% %+.2f; |d| <= 2 mm: %.3f of all\n",
              q(0.05) * 1e3, q(0.10) * 1e3, q(0.25) * 1e3, q(0.5) * 1e3, q(0.75) * 1e3, q(0.9) * 1e3, q(0.95) * 1e3,
              (double)within2 / std::max<std::size_t>(1, samples.size()));
  const double bin = 0.00025;
  const int nb = (int)std::ceil(max_distance / bin);
  std::vector<std::size_t> h(2 * nb, 0);
  for (double d : s) h[std::clamp((int)std::floor(d / bin) + nb, 0, 2 * nb - 1)]++;
  for (int b = 0; b < 2 * nb; ++b) {
    const double lo = (b - nb) * bin * 1e3;
    if (std::abs(lo) > 3.0) continue;
    std::printf("  [%+5.2f,%+5.2f) %6.3f %s\n", lo, lo + bin * 1e3, (double)h[b] / s.size(),
                std::string(std::min<std::size_t>(80, h[b] * 400 / std::max<std::size_t>(1, s.size())), '#').c_str());
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: %s DATASET MESH.ply [--max-mm D]\n", argv[0]);
    return 2;
  }
  double max_distance = 0.005;
  for (int a = 3; a < argc; ++a)
    if (!std::strcmp(argv[a], "--max-mm") && a + 1 < argc) max_distance = std::atof(argv[++a]) / 1000.0;
  DatasetOptions dopt;
  dopt.dataset_dir = argv[1];
  const Dataset ds = Dataset::Open(dopt);
  const auto gt_path = ds.GroundTruthMeshPath(false);
  if (!gt_path) {
    std::fprintf(stderr, "%s has no gt_mesh.ply\n", argv[1]);
    return 2;
  }
  const TriangleMesh gt = ReadPly(*gt_path), mesh = ReadPly(argv[2]);
  const BoundingBox& v = ds.bbox();
  std::vector<Eigen::Vector3d> mesh_samples, gt_samples;
  for (const auto& p : SampleSurface(mesh, 0.001, 1))
    if (v.Contains(p)) mesh_samples.push_back(p);
  for (const auto& p : SampleSurface(gt, 0.001, 2))
    if (v.Contains(p)) gt_samples.push_back(p);
  Report("reconstruction -> ground truth (+: outside the object)", mesh_samples, SignedSurfaceDistance(gt, max_distance),
         max_distance);
  Report("ground truth -> reconstruction (+: along the reconstruction's normals)", gt_samples,
         SignedSurfaceDistance(mesh, max_distance), max_distance);
  return 0;
}
