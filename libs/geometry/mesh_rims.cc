#include "geometry/mesh_rims.h"

#include <vector>

#include "geometry/mesh_topology.h"
#include "util/error.h"

namespace lfrecon {

void RimTrimOptions::Check() const {
  LFRECON_CHECK_OPTION(rounds >= 0);
  LFRECON_CHECK_OPTION(min_component_vertices >= 0);
}

namespace {

double TriangleArea(const TriangleMesh& m, const Eigen::Vector3i& t) {
  return 0.5 * (m.vertices[t[1]] - m.vertices[t[0]]).cross(m.vertices[t[2]] - m.vertices[t[0]]).cast<double>().norm();
}

}  // namespace

RimTrimStats TrimOpenRims(TriangleMesh* mesh, const RimTrimOptions& options) {
  options.Check();
  RimTrimStats stats;
  if (options.rounds == 0 || mesh->triangles.empty()) return stats;
  for (int round = 0; round < options.rounds; ++round) {
    const std::vector<unsigned char> open = OpenEdgeMasks(*mesh);
    const std::vector<char> large = VerticesOfLargeComponents(BuildVertexAdjacency(*mesh), options.min_component_vertices);
    std::vector<Eigen::Vector3i> kept;
    kept.reserve(mesh->triangles.size());
    for (std::size_t i = 0; i < mesh->triangles.size(); ++i) {
      const Eigen::Vector3i& t = mesh->triangles[i];
      if (open[i] && large[t[0]]) {
        ++stats.triangles_removed;
        stats.area_removed += TriangleArea(*mesh, t);
      } else {
        kept.push_back(t);
      }
    }
    if (kept.size() == mesh->triangles.size()) break;
    mesh->triangles.swap(kept);
  }
  const bool normals = mesh->HasNormals();
  mesh->RemoveUnreferencedVertices();
  if (normals) mesh->ComputeVertexNormals();
  return stats;
}

}  // namespace lfrecon
