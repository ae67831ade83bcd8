#include "refine/mesh_cleanup.h"

#include <Eigen/Geometry>

#include <numeric>
#include <vector>

namespace lfrecon {
namespace {

int Find(std::vector<int>& parent, int x) {
  while (parent[x] != x) x = parent[x] = parent[parent[x]];
  return x;
}

}  // namespace

TriangleMesh RemoveSmallComponents(const TriangleMesh& mesh, double min_area, ComponentFilterStats* stats) {
  ComponentFilterStats st;
  const std::size_t nv = mesh.vertices.size();
  std::vector<int> parent(nv);
  std::iota(parent.begin(), parent.end(), 0);
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const int a = Find(parent, t[0]);
    parent[Find(parent, t[1])] = a;
    parent[Find(parent, t[2])] = a;
  }
  std::vector<double> area(nv, 0.0);
  std::vector<char> has(nv, 0);
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3f a = mesh.vertices[t[0]], b = mesh.vertices[t[1]], c = mesh.vertices[t[2]];
    const int r = Find(parent, t[0]);
    area[r] += 0.5 * static_cast<double>((b - a).cross(c - a).norm());
    has[r] = 1;
  }
  for (std::size_t i = 0; i < nv; ++i)
    if (has[i]) {
      ++st.components;
      if (area[i] < min_area) ++st.components_removed, st.area_removed += area[i];
    }
  if (!(min_area > 0) || st.components_removed == 0) {
    st.components_removed = 0;
    st.area_removed = 0;
    if (stats) *stats = st;
    return mesh;
  }
  TriangleMesh out = mesh;
  out.triangles.clear();
  for (const Eigen::Vector3i& t : mesh.triangles) {
    if (area[Find(parent, t[0])] < min_area) ++st.triangles_removed;
    else out.triangles.push_back(t);
  }
  out.RemoveUnreferencedVertices();
  if (stats) *stats = st;
  return out;
}

}  // namespace lfrecon
