#include "geometry/triangle_mesh.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

namespace lfrecon {

void TriangleMesh::Append(const TriangleMesh& other) {
  const bool keep_normals = (vertices.empty() || HasNormals()) && other.HasNormals();
  const bool keep_colors = (vertices.empty() || HasColors()) && other.HasColors();
  const int offset = static_cast<int>(vertices.size());
  vertices.insert(vertices.end(), other.vertices.begin(), other.vertices.end());
  if (keep_normals) normals.insert(normals.end(), other.normals.begin(), other.normals.end());
  else normals.clear();
  if (keep_colors) colors.insert(colors.end(), other.colors.begin(), other.colors.end());
  else colors.clear();
  for (const auto& t : other.triangles) triangles.push_back(t + Eigen::Vector3i::Constant(offset));
}

void TriangleMesh::ComputeVertexNormals() {
  normals.assign(vertices.size(), Eigen::Vector3f::Zero());
  for (const auto& t : triangles) {
    const Eigen::Vector3f n = (vertices[t[1]] - vertices[t[0]]).cross(vertices[t[2]] - vertices[t[0]]);
    for (int k = 0; k < 3; ++k) normals[t[k]] += n;
  }
  for (auto& n : normals) {
    const float len = n.norm();
    if (len > 0) n /= len;
  }
}

void TriangleMesh::RemoveUnreferencedVertices() {
  std::vector<int> index(vertices.size(), -1);
  for (const auto& t : triangles)
    for (int k = 0; k < 3; ++k) index[t[k]] = 0;
  const bool has_normals = HasNormals(), has_colors = HasColors();
  int kept = 0;
  for (std::size_t i = 0; i < index.size(); ++i) {
    if (index[i] < 0) continue;
    index[i] = kept;
    vertices[kept] = vertices[i];
    if (has_normals) normals[kept] = normals[i];
    if (has_colors) colors[kept] = colors[i];
    ++kept;
  }
  vertices.resize(kept);
  if (has_normals) normals.resize(kept);
  if (has_colors) colors.resize(kept);
  for (auto& t : triangles)
    for (int k = 0; k < 3; ++k) t[k] = index[t[k]];
}

double TriangleMesh::SurfaceArea() const {
  double area = 0;
  for (const auto& t : triangles)
    area += 0.5 * (vertices[t[1]] - vertices[t[0]]).cross(vertices[t[2]] - vertices[t[0]]).norm();
  return area;
}

void TriangleMesh::Bounds(Eigen::Vector3f* min, Eigen::Vector3f* max) const {
  min->setConstant(std::numeric_limits<float>::max());
  max->setConstant(std::numeric_limits<float>::lowest());
  for (const auto& v : vertices) {
    *min = min->cwiseMin(v);
    *max = max->cwiseMax(v);
  }
}

bool RayBoxInterval(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, const BoundingBox& box, double* t_in,
                    double* t_out) {
  double t0 = 0, t1 = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (std::abs(dir[a]) < 1e-15) {
      if (origin[a] < box.min[a] || origin[a] > box.max[a]) t0 = 1, t1 = 0;
      continue;
    }
    double ta = (box.min[a] - origin[a]) / dir[a], tb = (box.max[a] - origin[a]) / dir[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  *t_in = t0;
  *t_out = t1;
  return t0 <= t1;
}

bool RayMeetsBox(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, const BoundingBox& box) {
  double t0, t1;
  return RayBoxInterval(origin, dir, box, &t0, &t1);
}

}  // namespace lfrecon
