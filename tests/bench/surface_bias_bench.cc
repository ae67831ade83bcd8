// Benchmark (not a test): is a reconstructed surface offset from the ground truth, and by how much?
//   surface_bias_bench DATASET MESH.ply [--max-mm D]
// Samples MESH every 1 mm (inside the dataset's V) and signs each sample's distance to the nearest
// ground-truth triangle by that triangle's normal (positive: outside the object, as gt_mesh.ply's
// triangles face outward). Prints the signed-distance quantiles of the samples within D mm
// (default 5) and a histogram in 0.25 mm bins, then the same from ground truth to MESH (positive:
// the ground truth lies outside the reconstruction). A surface grown or shrunk by a constant shows
// as a shifted median; a noisy but unbiased one as wide quantiles around 0.
#include <Eigen/Core>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#include "eval/mesh_metrics.h"
#include "io/dataset.h"
#include "io/ply.h"
#include "nearest_triangle.h"

using namespace lfrecon;

namespace {

void Report(const char* label, const std::vector<Eigen::Vector3d>& samples, const bench::NearestTriangle& to,
            double max_distance) {
  std::vector<double> s;
  std::size_t far = 0;
  for (const auto& p : samples) {
    const double d = to.Signed(p);
    if (!(std::abs(d) <= max_distance)) ++far;  // +inf beyond the grid's reach
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
  Report("reconstruction -> ground truth (+: outside the object)", mesh_samples, bench::NearestTriangle(gt, max_distance, 1),
         max_distance);
  Report("ground truth -> reconstruction (+: along the reconstruction's normals)", gt_samples,
         bench::NearestTriangle(mesh, max_distance, 1), max_distance);
  return 0;
}
