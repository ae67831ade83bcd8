#include "geometry/mesh_smoothing.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "geometry/mesh_topology.h"
#include "util/error.h"

namespace lfrecon {

void TaubinSmoothingOptions::Check() const {
  LFRECON_CHECK_OPTION(iterations >= 0);
  LFRECON_CHECK_OPTION(lambda > 0 && lambda < 1);
  LFRECON_CHECK_OPTION(mu < -lambda && mu > -1);
  LFRECON_CHECK_OPTION(max_displacement > 0);
  LFRECON_CHECK_OPTION(min_component_vertices >= 0);
}

TaubinSmoothingStats SmoothTaubin(TriangleMesh* mesh, const TaubinSmoothingOptions& options) {
  options.Check();
  TaubinSmoothingStats stats;
  const std::size_t n = mesh->vertices.size();
  if (options.iterations == 0 || n == 0 || mesh->triangles.empty()) return stats;
  const VertexAdjacency adj = BuildVertexAdjacency(*mesh);
  std::vector<char> moves = VerticesOfLargeComponents(adj, options.min_component_vertices);
  for (std::size_t i = 0; i < n; ++i)
    if (adj.Degree(i) == 0) moves[i] = 0;  // unreferenced vertex

  const std::vector<Eigen::Vector3f> input = mesh->vertices;
  std::vector<Eigen::Vector3f> next(n);
  const float max_d = static_cast<float>(std::min<double>(options.max_displacement, 1e30));
  auto step = [&](float factor) {
    const auto& cur = mesh->vertices;
    for (std::size_t i = 0; i < n; ++i) {
      if (!moves[i]) {
        next[i] = cur[i];
        continue;
      }
      Eigen::Vector3f mean = Eigen::Vector3f::Zero();
      for (int e = adj.offsets[i]; e < adj.offsets[i + 1]; ++e) mean += cur[adj.neighbours[e]];
      mean /= static_cast<float>(adj.Degree(i));
      Eigen::Vector3f p = cur[i] + factor * (mean - cur[i]);
      const Eigen::Vector3f d = p - input[i];
      const float len = d.norm();
      if (len > max_d) p = input[i] + d * (max_d / len);
      next[i] = p;
    }
    mesh->vertices.swap(next);
  };
  for (int it = 0; it < options.iterations; ++it) {
    step(static_cast<float>(options.lambda));
    step(static_cast<float>(options.mu));
  }

  double sum = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!moves[i]) continue;
    const float d = (mesh->vertices[i] - input[i]).norm();
    ++stats.vertices_moved;
    sum += d;
    if (d >= max_d * 0.999f) ++stats.vertices_capped;
  }
  stats.mean_displacement = stats.vertices_moved ? sum / stats.vertices_moved : 0;
  if (mesh->HasNormals()) mesh->ComputeVertexNormals();
  return stats;
}

}  // namespace lfrecon
