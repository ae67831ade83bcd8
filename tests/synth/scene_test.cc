#include "synth/scene.h"

#include <gtest/gtest.h>

#include <random>

#include "synth/gt_mesh.h"
#include "synth/scenes.h"
#include "util/error.h"

namespace lfrecon::synth {
namespace {

using Eigen::Vector3d;

Material Grey() { return Material::Flat({0.5f, 0.5f, 0.5f}); }

// Random rays towards a primitive: hits lie on its surface, and the analytic
// surface distance is 0 there.
void CheckHitsOnSurface(const Primitive& p, int* hits) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  Vector3d c;
  double r;
  p.BoundingSphere(&c, &r);
  if (!std::isfinite(r)) r = 1;
  // Aim at points of the surface (tessellation vertices), jittered a little.
  const TriangleMesh mesh = TessellatePrimitive(p);
  std::uniform_int_distribution<std::size_t> pick(0, mesh.vertices.size() - 1);
  for (int k = 0; k < 2000; ++k) {
    const Vector3d o = c + 3 * r * Vector3d(u(rng), u(rng), u(rng)).normalized();
    const Vector3d target = mesh.vertices[pick(rng)].cast<double>() +
                            0.01 * std::min(p.ThinSize(), r) * Vector3d(u(rng), u(rng), u(rng));
    const Vector3d d = target - o;
    double t;
    if (!p.Intersect(o, d, 0, 1e9, &t)) continue;
    ++*hits;
    EXPECT_LT(p.SurfaceDistance(o + t * d), 1e-12 * (1 + r)) << PrimitiveTypeName(p.type);
    // Nothing of the surface lies closer along the ray.
    for (double f : {0.25, 0.5, 0.9, 0.999}) EXPECT_GT(p.SurfaceDistance(o + f * t * d), 0.0);
  }
}

TEST(Primitive, IntersectionsLieOnTheSurface) {
  const Eigen::Matrix3d rot = Eigen::AngleAxisd(0.7, Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const std::vector<Primitive> prims = {
      Primitive::Sphere({0.1, 0.2, 0.3}, 0.2, Grey()),
      Primitive::Box({0, 0.1, 0}, {0.1, 0.2, 0.05}, Grey(), rot),
      Primitive::Cylinder({0, 0, 0}, {0.1, 0.3, 0.2}, 0.05, Grey()),
      Primitive::Cylinder({0, 0, 0}, {0.0, 0.0, 0.2}, 0.05, Grey(), true, false),
      Primitive::Cylinder({0, 0, 0}, {0.3, -0.1, 0.05}, 0.002, Grey()),
      Primitive::Rect({0, 0, 0.1}, {1, 0, 0}, {0, 1, 0.2}, 0.3, 0.1, Grey()),
  };
  for (const Primitive& p : prims) {
    int hits = 0;
    if (p.type == PrimitiveType::kPlane) {
      ASSERT_TRUE(p.IsBounded());
    }
    CheckHitsOnSurface(p, &hits);
    EXPECT_GT(hits, 300) << PrimitiveTypeName(p.type);  // corner targets of boxes and rects miss often
  }
  // An infinite plane.
  const Primitive plane = Primitive::Plane({0, 0, 0.1}, {0.2, 0.1, 1}, Grey());
  double t;
  ASSERT_TRUE(plane.Intersect({5, -3, 2}, {0.1, 0.2, -1}, 0, 1e9, &t));
  EXPECT_LT(plane.SurfaceDistance(Vector3d(5, -3, 2) + t * Vector3d(0.1, 0.2, -1)), 1e-12);
  EXPECT_FALSE(plane.Intersect({5, -3, 2}, {0.1, 0.2, 1}, 0, 1e9, &t));
}

TEST(Primitive, OpenCupShowsItsInsideAndDomeIsSeenFromInside) {
  const Primitive cup = Primitive::Cylinder({0, 0, 0}, {0, 0, 0.1}, 0.05, Grey(), true, false);
  double t;
  // Looking straight down into the cup: the bottom cap at z = 0.
  ASSERT_TRUE(cup.Intersect({0.01, 0, 1}, {0, 0, -1}, 0, 1e9, &t));
  EXPECT_NEAR(t, 1.0, 1e-12);
  // Looking down at an angle through the opening: the inner wall on the far side.
  ASSERT_TRUE(cup.Intersect({0.04, 0, 0.3}, {-0.09, 0, -0.25}, 0, 1e9, &t));
  EXPECT_NEAR(t, 1.0, 1e-12);  // at (-0.05, 0, 0.05)
  const Primitive closed = Primitive::Cylinder({0, 0, 0}, {0, 0, 0.1}, 0.05, Grey());
  ASSERT_TRUE(closed.Intersect({0.01, 0, 1}, {0, 0, -1}, 0, 1e9, &t));
  EXPECT_NEAR(t, 0.9, 1e-12);
  const Primitive dome = Primitive::Sphere({0, 0, 0}, 3, Grey());
  ASSERT_TRUE(dome.Intersect({0.5, 0, 0}, {1, 0, 0}, 0, 1e9, &t));
  EXPECT_NEAR(t, 2.5, 1e-12);
}

TEST(Scene, ThinFlagFollowsRadius) {
  Scene s;
  s.set_thin_radius(0.006);
  const int a = s.Add(Primitive::Cylinder({0, 0, 0}, {0, 0, 1}, 0.006, Grey()));
  const int b = s.Add(Primitive::Cylinder({0, 0, 0}, {0, 0, 1}, 0.0061, Grey()));
  const int c = s.Add(Primitive::Box({0, 0, 0}, {0.003, 0.004, 0.3}, Grey()));  // a stick
  const int d = s.Add(Primitive::Box({0, 0, 0}, {0.003, 0.1, 0.3}, Grey()));    // a plate
  const int e = s.Add(Primitive::Plane({0, 0, 0}, {0, 0, 1}, Grey()));
  EXPECT_TRUE(s.primitive(a).thin);
  EXPECT_FALSE(s.primitive(b).thin);
  EXPECT_TRUE(s.primitive(c).thin);
  EXPECT_FALSE(s.primitive(d).thin);
  EXPECT_FALSE(s.primitive(e).thin);
  s.set_thin_radius(0.01);
  EXPECT_TRUE(s.primitive(b).thin);
}

TEST(Scene, NearestHitWins) {
  Scene s;
  s.Add(Primitive::Sphere({0, 0, 5}, 1, Grey()));
  s.Add(Primitive::Sphere({0, 0, 2}, 0.5, Grey()));
  const Hit h = s.Intersect({0, 0, 0}, {0, 0, 1});
  EXPECT_EQ(h.id, 1);
  EXPECT_NEAR(h.t, 1.5, 1e-12);
  EXPECT_FALSE(s.Intersect({0, 0, 0}, {0, 1, 0}).ok());
}

TEST(NamedScenes, UnknownNameListsTheNames) {
  try {
    MakeNamedScene("teapot");
    FAIL() << "expected OptionError";
  } catch (const OptionError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("teapot"), std::string::npos);
    for (const std::string& n : SceneNames()) EXPECT_NE(msg.find(n), std::string::npos) << msg;
  }
}

// Foreground primitives lie inside V, background ones outside; the tabletop
// has thin textured and textureless parts, and the table plane is background.
TEST(NamedScenes, ForegroundInsideVAndBackgroundOutside) {
  for (const std::string& name : SceneNames()) {
    const SceneSetup setup = MakeNamedScene(name, 1);
    const Scene& s = setup.scene;
    const BoundingBox& V = s.foreground_bbox();
    ASSERT_TRUE(V.IsValid()) << name;
    int fg = 0;
    for (const Primitive& p : s.primitives()) {
      fg += p.foreground;
      const TriangleMesh m = TessellatePrimitive(p);
      for (const auto& v : m.vertices) {
        const bool inside = V.Contains(v.cast<double>());
        ASSERT_EQ(inside, p.foreground) << name << "/" << p.name;
      }
    }
    EXPECT_GT(fg, 0) << name;
    EXPECT_GT(V.min.z(), 0.0) << name << ": the table z = 0 must lie outside V";
    // The rig looks at V's centre from outside V.
    const Vector3d eye(setup.path.target.x() + setup.path.radius, setup.path.target.y(), setup.path.height);
    EXPECT_FALSE(V.Contains(eye)) << name;
  }
  const Scene s = MakeNamedScene("tabletop").scene;
  int thin_textured = 0, thin_flat = 0;
  for (const Primitive& p : s.primitives()) {
    if (!p.thin) continue;
    EXPECT_TRUE(p.foreground) << p.name;
    (p.material.IsTextured() ? thin_textured : thin_flat)++;
  }
  EXPECT_GE(thin_textured, 3);
  EXPECT_GE(thin_flat, 1);
}

TEST(NamedScenes, SeedShiftsTexturesOnly) {
  const Scene a = MakeNamedScene("sphere", 1).scene, b = MakeNamedScene("sphere", 2).scene;
  ASSERT_EQ(a.NumPrimitives(), b.NumPrimitives());
  const Vector3d p(0, 0.15, 0.25);
  EXPECT_EQ(a.primitive(0).center, b.primitive(0).center);
  EXPECT_GT((a.Albedo(0, p) - b.Albedo(0, p)).norm() +
                (a.Albedo(0, p + Vector3d(0.01, 0, 0)) - b.Albedo(0, p + Vector3d(0.01, 0, 0))).norm(),
            1e-3);
}

}  // namespace
}  // namespace lfrecon::synth
