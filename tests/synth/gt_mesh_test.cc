#include "synth/gt_mesh.h"

#include <gtest/gtest.h>

#include "synth/scenes.h"

namespace lfrecon::synth {
namespace {

using Eigen::Vector3d;

// Distance of p to the nearest surface of the primitives selected by `use`.
template <typename Pred>
double NearestSurface(const Scene& s, const Vector3d& p, Pred use) {
  double best = std::numeric_limits<double>::infinity();
  for (const Primitive& prim : s.primitives())
    if (use(prim)) best = std::min(best, prim.SurfaceDistance(p));
  return best;
}

TEST(GroundTruthMesh, VerticesAndFacesLieOnTheSurfaces) {
  const double tol = 5e-5;
  for (const std::string& name : SceneNames()) {
    const Scene s = MakeNamedScene(name).scene;
    for (const Primitive& p : s.primitives()) {
      if (!p.IsBounded()) continue;
      const TriangleMesh m = TessellatePrimitive(p, tol);
      ASSERT_FALSE(m.triangles.empty()) << p.name;
      ASSERT_TRUE(m.HasNormals());
      ASSERT_TRUE(m.HasColors());
      Vector3d c;
      double r;
      p.BoundingSphere(&c, &r);
      const double float_eps = 4e-7 * (c.norm() + r);  // vertices are stored as float
      for (const auto& v : m.vertices) ASSERT_LT(p.SurfaceDistance(v.cast<double>()), float_eps) << p.name;
      for (const auto& t : m.triangles) {
        const Vector3d a = m.vertices[t[0]].cast<double>(), b = m.vertices[t[1]].cast<double>(),
                       cc = m.vertices[t[2]].cast<double>();
        // Chord error: the tolerance holds for the foreground (background domes hit the segment cap).
        if (p.foreground) {
          ASSERT_LT(p.SurfaceDistance((a + b + cc) / 3), tol + float_eps) << p.name;
        }
        // Outward orientation: the face normal agrees with the vertex normals.
        const Vector3d n = (b - a).cross(cc - a);
        if (n.norm() > 1e-12) {
          EXPECT_GT(n.dot(m.normals[t[0]].cast<double>()), 0) << p.name;
        }
      }
    }
  }
}

TEST(GroundTruthMesh, FullAndThinMeshesSelectTheRightPrimitives) {
  const Scene s = MakeNamedScene("tabletop").scene;
  const TriangleMesh full = GroundTruthMesh(s, false), thin = GroundTruthMesh(s, true);
  std::size_t full_v = 0, thin_v = 0;
  for (const Primitive& p : s.primitives()) {
    const std::size_t n = TessellatePrimitive(p).vertices.size();
    if (p.foreground) full_v += n;
    if (p.foreground && p.thin) thin_v += n;
  }
  EXPECT_EQ(full.vertices.size(), full_v);
  EXPECT_EQ(thin.vertices.size(), thin_v);
  ASSERT_GT(thin_v, 0u);
  ASSERT_LT(thin_v, full_v);
  for (const auto& v : thin.vertices)
    ASSERT_LT(NearestSurface(s, v.cast<double>(), [](const Primitive& p) { return p.thin && p.foreground; }),
              1e-6);
  for (const auto& v : full.vertices) {
    ASSERT_LT(NearestSurface(s, v.cast<double>(), [](const Primitive& p) { return p.foreground; }), 1e-6);
    ASSERT_TRUE(s.foreground_bbox().Contains(v.cast<double>()));
  }
  // A scene without thin parts gives an empty thin mesh.
  EXPECT_TRUE(GroundTruthMesh(MakeNamedScene("sphere").scene, true).vertices.empty());
}

TEST(GroundTruthMesh, SphereAreaConverges) {
  Scene s;
  s.Add(Primitive::Sphere({0, 0, 0}, 0.1, Material::Flat({1, 1, 1})).Foreground());
  const double area = GroundTruthMesh(s).SurfaceArea();
  EXPECT_NEAR(area, 4 * M_PI * 0.01, 4 * M_PI * 0.01 * 2e-3);
}

}  // namespace
}  // namespace lfrecon::synth
