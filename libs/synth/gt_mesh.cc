#include "synth/gt_mesh.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>

namespace lfrecon::synth {
namespace {

using Eigen::Vector3d;

// Segments of a circle of radius r whose chords stay within `tol` of it.
int CircleSegments(double r, double tol) {
  const double ratio = std::clamp(1.0 - tol / r, -1.0, 1.0);
  const double n = M_PI / std::acos(ratio);
  return std::clamp(static_cast<int>(std::ceil(n)), 12, 512);
}

class MeshBuilder {
 public:
  explicit MeshBuilder(const Material& m) : material_(m) {}
  int Vertex(const Vector3d& p, const Vector3d& n) {
    mesh_.vertices.push_back(p.cast<float>());
    mesh_.normals.push_back(n.normalized().cast<float>());
    // Colour at the stored (float) position, as seen in the images.
    const Eigen::Vector3f a = material_.Albedo(p);
    Color3u8 c;
    for (int k = 0; k < 3; ++k)
      c[k] = static_cast<std::uint8_t>(std::lround(std::clamp(a[k], 0.0f, 1.0f) * 255.0f));
    mesh_.colors.push_back(c);
    return static_cast<int>(mesh_.vertices.size()) - 1;
  }
  void Triangle(int a, int b, int c) { mesh_.triangles.emplace_back(a, b, c); }
  // Quad a-b-c-d counter-clockwise seen from outside.
  void Quad(int a, int b, int c, int d) {
    Triangle(a, b, c);
    Triangle(a, c, d);
  }
  TriangleMesh Take() { return std::move(mesh_); }

 private:
  const Material& material_;
  TriangleMesh mesh_;
};

TriangleMesh Sphere(const Primitive& p, double tol) {
  MeshBuilder b(p.material);
  // Half the tolerance on the circles keeps the 2D patches' centres within it too.
  const int n_lon = CircleSegments(p.radius, 0.5 * tol);
  const int n_lat = std::max(6, n_lon / 2);
  auto point = [&](double theta, double phi) {
    return Vector3d(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta));
  };
  const int north = b.Vertex(p.center + p.radius * Vector3d::UnitZ(), Vector3d::UnitZ());
  std::vector<int> rings;  // first vertex of each interior ring
  for (int i = 1; i < n_lat; ++i) {
    rings.push_back(north + 1 + (i - 1) * n_lon);
    const double theta = M_PI * i / n_lat;
    for (int j = 0; j < n_lon; ++j) {
      const Vector3d n = point(theta, 2.0 * M_PI * j / n_lon);
      b.Vertex(p.center + p.radius * n, n);
    }
  }
  const int south = b.Vertex(p.center - p.radius * Vector3d::UnitZ(), -Vector3d::UnitZ());
  for (int j = 0; j < n_lon; ++j) {
    const int j1 = (j + 1) % n_lon;
    b.Triangle(north, rings.front() + j, rings.front() + j1);
    b.Triangle(south, rings.back() + j1, rings.back() + j);
  }
  for (std::size_t i = 0; i + 1 < rings.size(); ++i)
    for (int j = 0; j < n_lon; ++j) {
      const int j1 = (j + 1) % n_lon;
      b.Quad(rings[i] + j, rings[i + 1] + j, rings[i + 1] + j1, rings[i] + j1);
    }
  return b.Take();
}

TriangleMesh Box(const Primitive& p) {
  MeshBuilder b(p.material);
  // Each face separately so normals stay sharp.
  for (int axis = 0; axis < 3; ++axis) {
    for (int sign = -1; sign <= 1; sign += 2) {
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      const Vector3d n = sign * p.axes.col(axis);
      const Vector3d c = p.center + sign * p.half_size[axis] * p.axes.col(axis);
      const Vector3d du = p.half_size[u] * p.axes.col(u), dv = p.half_size[v] * p.axes.col(v);
      const int i0 = b.Vertex(c - du - dv, n), i1 = b.Vertex(c + du - dv, n);
      const int i2 = b.Vertex(c + du + dv, n), i3 = b.Vertex(c - du + dv, n);
      // (u, v, axis) is right-handed, so u x v = +axis.
      if (sign > 0)
        b.Quad(i0, i1, i2, i3);
      else
        b.Quad(i0, i3, i2, i1);
    }
  }
  return b.Take();
}

TriangleMesh Cylinder(const Primitive& p, double tol) {
  MeshBuilder b(p.material);
  const int n = CircleSegments(p.radius, tol);
  const Vector3d ex = p.axes.col(0), ey = p.axes.col(1), ez = p.axes.col(2);
  const Vector3d p1 = p.CylinderEnd();
  auto radial = [&](int j) {
    const double phi = 2.0 * M_PI * j / n;
    return Vector3d(std::cos(phi) * ex + std::sin(phi) * ey);
  };
  std::vector<int> bottom(n), top(n);
  for (int j = 0; j < n; ++j) {
    const Vector3d r = radial(j);
    bottom[j] = b.Vertex(p.center + p.radius * r, r);
    top[j] = b.Vertex(p1 + p.radius * r, r);
  }
  for (int j = 0; j < n; ++j) {
    const int j1 = (j + 1) % n;
    b.Quad(bottom[j], bottom[j1], top[j1], top[j]);
  }
  for (int end = 0; end < 2; ++end) {
    if (!(end == 0 ? p.cap0 : p.cap1)) continue;
    const Vector3d c = end == 0 ? p.center : p1;
    const Vector3d normal = end == 0 ? Vector3d(-ez) : ez;
    const int centre = b.Vertex(c, normal);
    std::vector<int> ring(n);
    for (int j = 0; j < n; ++j) ring[j] = b.Vertex(c + p.radius * radial(j), normal);
    for (int j = 0; j < n; ++j) {
      const int j1 = (j + 1) % n;
      if (end == 0)
        b.Triangle(centre, ring[j1], ring[j]);
      else
        b.Triangle(centre, ring[j], ring[j1]);
    }
  }
  return b.Take();
}

TriangleMesh Rect(const Primitive& p) {
  MeshBuilder b(p.material);
  const Vector3d n = p.axes.col(2);
  const Vector3d du = p.half_size.x() * p.axes.col(0), dv = p.half_size.y() * p.axes.col(1);
  const int i0 = b.Vertex(p.center - du - dv, n), i1 = b.Vertex(p.center + du - dv, n);
  const int i2 = b.Vertex(p.center + du + dv, n), i3 = b.Vertex(p.center - du + dv, n);
  b.Quad(i0, i1, i2, i3);
  return b.Take();
}

}  // namespace

TriangleMesh TessellatePrimitive(const Primitive& p, double tolerance) {
  switch (p.type) {
    case PrimitiveType::kSphere:
      return Sphere(p, tolerance);
    case PrimitiveType::kBox:
      return Box(p);
    case PrimitiveType::kCylinder:
      return Cylinder(p, tolerance);
    case PrimitiveType::kPlane:
      if (!p.IsBounded()) {
        spdlog::warn("synth: primitive '{}' is an infinite plane; it is left out of the ground-truth mesh",
                     p.name);
        return TriangleMesh();
      }
      return Rect(p);
  }
  return TriangleMesh();
}

TriangleMesh GroundTruthMesh(const Scene& scene, bool thin_only, double tolerance) {
  TriangleMesh mesh;
  for (const Primitive& p : scene.primitives()) {
    if (!p.foreground || (thin_only && !p.thin)) continue;
    mesh.Append(TessellatePrimitive(p, tolerance));
  }
  return mesh;
}

}  // namespace lfrecon::synth
