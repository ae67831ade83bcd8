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

// Does the ray from `origin` along `dir` meet `box` (at a parameter >= 0)? Slab test.
bool RayMeetsBox(const Eigen::Vector3d& origin, const Eigen::Vector3d& dir, const BoundingBox& box);

}  // namespace lfrecon
