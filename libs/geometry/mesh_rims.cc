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

// Drops the vertices no triangle uses, keeping the order of the others.
void DropUnusedVertices(TriangleMesh* mesh) {
  std::vector<int> index(mesh->vertices.size(), -1);
  for (const auto& t : mesh->triangles)
    for (int k = 0; k < 3; ++k) index[t[k]] = 0;
  const bool normals = mesh->HasNormals(), colors = mesh->HasColors();
  int kept = 0;
  for (std::size_t i = 0; i < index.size(); ++i) {
    if (index[i] < 0) continue;
    index[i] = kept;
    mesh->vertices[kept] = mesh->vertices[i];
    if (normals) mesh->normals[kept] = mesh->normals[i];
    if (colors) mesh->colors[kept] = mesh->colors[i];
    ++kept;
  }
  mesh->vertices.resize(kept);
  if (normals) mesh->normals.resize(kept);
  if (colors) mesh->colors.resize(kept);
  for (auto& t : mesh->triangles)
    for (int k = 0; k < 3; ++k) t[k] = index[t[k]];
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
  DropUnusedVertices(mesh);
  if (normals) mesh->ComputeVertexNormals();
  return stats;
}

}  // namespace lfrecon
