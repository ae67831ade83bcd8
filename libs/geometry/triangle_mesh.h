#pragma once
// A triangle mesh with optional per-vertex normals and colours (Open3D's
// geometry::TriangleMesh in spirit). Coordinates in metres, world frame.
#include <Eigen/Core>
#include <cstdint>
#include <vector>

namespace lfrecon {

using Color3u8 = Eigen::Matrix<std::uint8_t, 3, 1>;

struct TriangleMesh {
  std::vector<Eigen::Vector3f> vertices;
  std::vector<Eigen::Vector3f> normals;  // empty or one per vertex
  std::vector<Color3u8> colors;          // empty or one per vertex (RGB)
  std::vector<Eigen::Vector3i> triangles;

  bool HasNormals() const { return !normals.empty() && normals.size() == vertices.size(); }
  bool HasColors() const { return !colors.empty() && colors.size() == vertices.size(); }
  // Appends another mesh (its attributes are kept only if both meshes have them).
  void Append(const TriangleMesh& other);
  // Area-weighted vertex normals from the triangles.
  void ComputeVertexNormals();
  // Drops the vertices no triangle uses (their normals and colours with them),
  // keeping the order of the others (Open3D's RemoveUnreferencedVertices).
  void RemoveUnreferencedVertices();
  double SurfaceArea() const;
  // Axis-aligned bounds of the vertices.
  void Bounds(Eigen::Vector3f* min, Eigen::Vector3f* max) const;
};

// Axis-aligned box, e.g. the foreground volume V.
struct BoundingBox {
  Eigen::Vector3d min = Eigen::Vector3d::Zero();
  Eigen::Vector3d max = Eigen::Vector3d::Zero();

  bool IsValid() const { return min.allFinite() && max.allFinite() && (max.array() > min.array()).all(); }
  bool Contains(const Eigen::Vector3d& p) const {
    return (p.array() >= min.array()).all() && (p.array() <= max.array()).all();
  }
  Eigen::Vector3d Center() const { return 0.5 * (min + max); }
  Eigen::Vector3d Extent() const { return max - min; }
  // The box grown by `margin` (metres) on every side.
  BoundingBox Grown(double margin) const {
    BoundingBox b = *this;
    b.min.array() -= margin;
    b.max.array() += margin;
    return b;
  }
};

// The point of triangle abc nearest to p (Ericson, Real-Time Collision
// Detection §5.1.5). Inline: distance evaluation calls it per sample and triangle.
inline Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                              const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return a + (d1 / (d1 - d3)) * ab;
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return a + (d2 / (d2 - d6)) * ac;
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return b + ((d4 - d3) / ((d4 - d3) + (d5 - d6))) * (c - b);
  const double denom = 1.0 / (va + vb + vc);
  return a + ab * (vb * denom) + ac * (vc * denom);
}

// The parameters [*t_in, *t_out] (t >= 0) at which origin + t·dir lies in
// `box` (slab method); false, with *t_in > *t_out, when it never does.
bool RayBoxInterval(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, const BoundingBox& box, double* t_in,
                    double* t_out);

// Does the ray from `origin` along `dir` meet `box` (at a parameter >= 0)?
bool RayMeetsBox(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, const BoundingBox& box);

}  // namespace lfrecon
