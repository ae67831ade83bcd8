#include "synth/scenes.h"

#include <Eigen/Geometry>
#include <cmath>

#include "util/error.h"

namespace lfrecon::synth {
namespace {

using Eigen::Vector3d;
using Eigen::Vector3f;

Eigen::Matrix3d RotZ(double deg) {
  return Eigen::AngleAxisd(deg * M_PI / 180.0, Vector3d::UnitZ()).toRotationMatrix();
}

BoundingBox Box3(const Vector3d& min, const Vector3d& max) {
  BoundingBox b;
  b.min = min;
  b.max = max;
  return b;
}

// The dome is a big textured sphere around everything: every ray hits
// something, as in a real room.
void AddDome(Scene* s, const Vector3d& center, double radius) {
  Material m = Material::Noise({0.35f, 0.42f, 0.55f}, {0.8f, 0.82f, 0.86f}, 0.22);
  s->Add(Primitive::Sphere(center, radius, m).Named("dome"));
}

void AddFloor(Scene* s, double half, const Material& m, const std::string& name = "floor") {
  s->Add(Primitive::Rect(Vector3d::Zero(), Vector3d::UnitX(), Vector3d::UnitY(), half, half, m).Named(name));
}

CameraPathOptions Rig(const Scene& s, double radius, double height) {
  CameraPathOptions p;
  p.target = s.foreground_bbox().Center();
  p.radius = radius;
  p.height = height;
  return p;
}

SceneSetup Tabletop() {
  SceneSetup out{Scene("tabletop"), {}};
  Scene& s = out.scene;
  s.set_foreground_bbox(Box3({-0.26, -0.26, 0.005}, {0.26, 0.26, 0.42}));

  // --- Foreground (inside V; everything floats >= 7 mm above V's floor so
  // V's bottom face never cuts a primitive).
  s.Add(Primitive::Sphere({-0.11, 0.09, 0.10}, 0.08,
                          Material::Noise({0.35f, 0.15f, 0.06f}, {0.95f, 0.7f, 0.35f}, 0.018))
            .Named("sphere")
            .Foreground());
  s.Add(Primitive::Box({0.12, 0.11, 0.075}, {0.06, 0.045, 0.065},
                       Material::Checker({0.12f, 0.2f, 0.45f}, {0.9f, 0.88f, 0.75f}, 0.02), RotZ(25))
            .Named("box")
            .Foreground());
  // An open cup: bottom cap only, so views from above see its inside.
  s.Add(Primitive::Cylinder(
            {0.0, -0.13, 0.012}, {0.0, -0.13, 0.13}, 0.05,
            Material::Stripes({0.7f, 0.1f, 0.1f}, {0.95f, 0.92f, 0.9f}, 0.015, Vector3d::UnitZ()), true,
            false)
            .Named("cup")
            .Foreground());
  // A stool: plate on four legs 1.5-2.5 mm in radius (2-3 px at 640x360).
  const Vector3d stool(0.15, -0.12, 0.17);
  s.Add(Primitive::Box(stool, {0.055, 0.05, 0.006},
                       Material::Noise({0.1f, 0.35f, 0.12f}, {0.7f, 0.9f, 0.5f}, 0.012))
            .Named("stool_top")
            .Foreground());
  const Material leg_materials[4] = {
      Material::Noise({0.2f, 0.12f, 0.05f}, {0.9f, 0.75f, 0.5f}, 0.006),
      Material::Flat({0.92f, 0.85f, 0.55f}),  // textureless on purpose
      Material::Stripes({0.1f, 0.1f, 0.1f}, {0.9f, 0.9f, 0.9f}, 0.008, Vector3d::UnitZ()),
      Material::Noise({0.15f, 0.15f, 0.3f}, {0.8f, 0.8f, 0.95f}, 0.006),
  };
  const double leg_radius[4] = {0.002, 0.002, 0.0015, 0.0025};
  for (int k = 0; k < 4; ++k) {
    const double dx = (k & 1) ? 0.045 : -0.045, dy = (k & 2) ? 0.04 : -0.04;
    const Vector3d top = stool + Vector3d(dx, dy, -0.006);
    s.Add(Primitive::Cylinder({top.x(), top.y(), 0.012}, top, leg_radius[k], leg_materials[k], true, false)
              .Named("stool_leg" + std::to_string(k))
              .Foreground());
  }
  s.Add(Primitive::Cylinder({-0.2, -0.2, 0.012}, {-0.06, -0.06, 0.32}, 0.0015,
                            Material::Noise({0.1f, 0.08f, 0.05f}, {0.85f, 0.8f, 0.6f}, 0.006))
            .Named("stick")
            .Foreground());
  s.Add(Primitive::Cylinder({-0.22, 0.22, 0.015}, {-0.20, -0.02, 0.40}, 0.001,
                            Material::Flat({0.08f, 0.08f, 0.1f}))
            .Named("wire")
            .Foreground());  // 1 px, textureless, dark
  const Vector3d antenna0(-0.11, 0.09, 0.18), antenna1(-0.07, 0.13, 0.36);
  s.Add(Primitive::Cylinder(
            antenna0, antenna1, 0.0025,
            Material::Stripes({0.1f, 0.1f, 0.35f}, {0.95f, 0.95f, 0.6f}, 0.01, antenna1 - antenna0), false,
            false)
            .Named("antenna")
            .Foreground());
  s.Add(Primitive::Sphere(antenna1 + 0.004 * (antenna1 - antenna0).normalized(), 0.005,
                          Material::Noise({0.5f, 0.0f, 0.3f}, {1.0f, 0.7f, 0.9f}, 0.004))
            .Named("bead")
            .Foreground());
  const Vector3d post0(0.05, 0.22, 0.012), post1(0.05, 0.22, 0.24);
  s.Add(Primitive::Cylinder(post0, post1, 0.0025,
                            Material::Noise({0.3f, 0.2f, 0.1f}, {0.95f, 0.85f, 0.7f}, 0.006))
            .Named("post")
            .Foreground());
  s.Add(Primitive::Cylinder(post1, {0.23, 0.0, 0.24}, 0.003, Material::Flat({0.95f, 0.95f, 0.92f}))
            .Named("rail")
            .Foreground());  // textureless, white

  // --- Background (outside V): table, walls, clutter, dome.
  Material table = Material::Stripes({0.45f, 0.27f, 0.12f}, {0.85f, 0.65f, 0.42f}, 0.025, {1.0, 0.3, 0.0});
  table.detail = 0.5;
  AddFloor(&s, 1.5, table, "table");
  const double wall_half = 1.5, wall_h = 0.75;
  const Material walls[4] = {
      Material::Noise({0.25f, 0.3f, 0.2f}, {0.85f, 0.9f, 0.75f}, 0.07),
      Material::Checker({0.3f, 0.25f, 0.35f}, {0.9f, 0.85f, 0.8f}, 0.15),
      Material::Noise({0.4f, 0.2f, 0.2f}, {0.95f, 0.8f, 0.7f}, 0.07),
      Material::Stripes({0.2f, 0.3f, 0.4f}, {0.8f, 0.85f, 0.9f}, 0.12, Vector3d::UnitX()),
  };
  s.Add(Primitive::Rect({wall_half, 0, wall_h}, Vector3d::UnitY(), Vector3d::UnitZ(), wall_half, wall_h,
                        walls[0])
            .Named("wall_px"));
  s.Add(Primitive::Rect({-wall_half, 0, wall_h}, Vector3d::UnitY(), Vector3d::UnitZ(), wall_half, wall_h,
                        walls[1])
            .Named("wall_nx"));
  s.Add(Primitive::Rect({0, wall_half, wall_h}, Vector3d::UnitX(), Vector3d::UnitZ(), wall_half, wall_h,
                        walls[2])
            .Named("wall_py"));
  s.Add(Primitive::Rect({0, -wall_half, wall_h}, Vector3d::UnitX(), Vector3d::UnitZ(), wall_half, wall_h,
                        walls[3])
            .Named("wall_ny"));
  s.Add(Primitive::Box({0.48, -0.40, 0.035}, {0.05, 0.07, 0.035},
                       Material::Checker({0.5f, 0.35f, 0.1f}, {0.95f, 0.9f, 0.6f}, 0.02), RotZ(15))
            .Named("crate"));
  s.Add(Primitive::Box({-1.1, 0.75, 0.2}, {0.15, 0.25, 0.2},
                       Material::Noise({0.2f, 0.2f, 0.2f}, {0.8f, 0.75f, 0.7f}, 0.04), RotZ(40))
            .Named("shelf"));
  s.Add(Primitive::Cylinder(
            {-0.6, -1.05, 0.0}, {-0.6, -1.05, 0.35}, 0.12,
            Material::Stripes({0.3f, 0.15f, 0.05f}, {0.75f, 0.55f, 0.3f}, 0.04, Vector3d::UnitZ()))
            .Named("barrel"));
  s.Add(Primitive::Sphere({1.05, -0.85, 0.15}, 0.15,
                          Material::Noise({0.1f, 0.3f, 0.3f}, {0.7f, 0.95f, 0.9f}, 0.04))
            .Named("ball"));
  s.Add(Primitive::Box({0.9, 1.0, 0.3}, {0.2, 0.1, 0.3},
                       Material::Checker({0.15f, 0.15f, 0.15f}, {0.85f, 0.85f, 0.85f}, 0.05))
            .Named("tall_box"));
  AddDome(&s, Vector3d::Zero(), 3.5);

  out.path = Rig(s, 0.9, 0.95);
  return out;
}

SceneSetup SphereScene() {
  SceneSetup out{Scene("sphere"), {}};
  Scene& s = out.scene;
  s.set_foreground_bbox(Box3({-0.16, -0.16, 0.09}, {0.16, 0.16, 0.41}));
  s.Add(Primitive::Sphere({0, 0, 0.25}, 0.15, Material::Noise({0.3f, 0.1f, 0.05f}, {0.95f, 0.8f, 0.5f}, 0.02))
            .Named("sphere")
            .Foreground());
  Material floor = Material::Checker({0.2f, 0.25f, 0.3f}, {0.8f, 0.85f, 0.9f}, 0.1);
  floor.detail = 0.5;
  AddFloor(&s, 2.0, floor);
  AddDome(&s, Vector3d::Zero(), 3.0);
  out.path = Rig(s, 0.9, 0.55);
  return out;
}

SceneSetup PlaneScene() {
  SceneSetup out{Scene("plane"), {}};
  Scene& s = out.scene;
  // Normal u x v = +x: frame 0 looks at it from azimuth -30 degrees, the middle frame head-on.
  s.set_foreground_bbox(Box3({-0.01, -0.61, 0.04}, {0.01, 0.61, 0.96}));
  s.Add(Primitive::Rect({0, 0, 0.5}, Vector3d::UnitY(), Vector3d::UnitZ(), 0.6, 0.45,
                        Material::Noise({0.15f, 0.2f, 0.1f}, {0.9f, 0.85f, 0.6f}, 0.012))
            .Named("plane")
            .Foreground());
  AddDome(&s, {0, 0, 0.5}, 3.0);
  out.path = Rig(s, 0.9, 0.5);
  out.path.start_angle_deg = -30;
  out.path.loops = 1.0 / 6.0;
  return out;
}

SceneSetup ThinCylinderScene() {
  SceneSetup out{Scene("thin_cylinder"), {}};
  Scene& s = out.scene;
  s.set_foreground_bbox(Box3({-0.03, -0.03, 0.04}, {0.03, 0.03, 0.46}));
  // 1.8 mm radius: 2.5 px wide at 0.9 m with 640 px and a 55-degree field of view.
  s.Add(Primitive::Cylinder({0, 0, 0.05}, {0, 0, 0.45}, 0.0018, Material::Flat({0.93f, 0.93f, 0.9f}))
            .Named("thin_cylinder")
            .Foreground());
  AddFloor(&s, 2.0, Material::Noise({0.2f, 0.15f, 0.1f}, {0.75f, 0.6f, 0.45f}, 0.03));
  s.Add(Primitive::Sphere(Vector3d::Zero(), 2.0,
                          Material::Noise({0.08f, 0.1f, 0.15f}, {0.6f, 0.6f, 0.65f}, 0.04))
            .Named("dome"));
  out.path = Rig(s, 0.9, 0.35);
  return out;
}

SceneSetup OcclusionScene() {
  SceneSetup out{Scene("occlusion"), {}};
  Scene& s = out.scene;
  s.set_foreground_bbox(Box3({-0.25, -0.25, 0.01}, {0.25, 0.25, 0.40}));
  s.Add(
      Primitive::Cylinder({0, 0, 0.015}, {0, 0, 0.32}, 0.035,
                          Material::Stripes({0.1f, 0.3f, 0.1f}, {0.85f, 0.95f, 0.7f}, 0.02, {0.0, 0.3, 1.0}))
          .Named("pillar")
          .Foreground());
  s.Add(Primitive::Sphere({0.16, 0.02, 0.09}, 0.07,
                          Material::Noise({0.4f, 0.1f, 0.1f}, {1.0f, 0.75f, 0.6f}, 0.015))
            .Named("sphere_a")
            .Foreground());
  s.Add(Primitive::Sphere({-0.15, 0.06, 0.12}, 0.09,
                          Material::Noise({0.1f, 0.1f, 0.4f}, {0.7f, 0.8f, 1.0f}, 0.015))
            .Named("sphere_b")
            .Foreground());
  s.Add(Primitive::Box({0.02, 0.16, 0.085}, {0.05, 0.05, 0.07},
                       Material::Checker({0.35f, 0.2f, 0.05f}, {0.95f, 0.9f, 0.5f}, 0.02), RotZ(20))
            .Named("box_a")
            .Foreground());
  s.Add(Primitive::Box({0.0, -0.15, 0.06}, {0.07, 0.03, 0.045},
                       Material::Noise({0.25f, 0.25f, 0.25f}, {0.95f, 0.95f, 0.9f}, 0.012), RotZ(-30))
            .Named("box_b")
            .Foreground());
  AddFloor(&s, 2.0, Material::Noise({0.25f, 0.2f, 0.15f}, {0.8f, 0.7f, 0.55f}, 0.03));
  AddDome(&s, Vector3d::Zero(), 3.0);
  out.path = Rig(s, 0.9, 0.35);
  return out;
}

}  // namespace

const std::vector<std::string>& SceneNames() {
  static const std::vector<std::string> names = {"tabletop", "sphere", "plane", "thin_cylinder", "occlusion"};
  return names;
}

void RandomizeTextureOffsets(Scene* scene, std::uint64_t seed) {
  // Scene has no mutable access to primitives; rebuild it with shifted materials.
  Scene out(scene->name());
  out.set_foreground_bbox(scene->foreground_bbox());
  out.set_thin_radius(scene->thin_radius());
  out.set_background_color(scene->background_color());
  for (int i = 0; i < scene->NumPrimitives(); ++i) {
    Primitive p = scene->primitive(i);
    const std::uint64_t h = HashCombine(seed, static_cast<std::uint64_t>(i) + 1);
    for (int k = 0; k < 3; ++k)
      p.material.offset[k] = 97.0 * HashToUnit(HashCombine(h, static_cast<std::uint64_t>(k)));
    out.Add(std::move(p));
  }
  *scene = std::move(out);
}

SceneSetup MakeNamedScene(const std::string& name, std::uint64_t seed) {
  SceneSetup setup;
  if (name == "tabletop")
    setup = Tabletop();
  else if (name == "sphere")
    setup = SphereScene();
  else if (name == "plane")
    setup = PlaneScene();
  else if (name == "thin_cylinder")
    setup = ThinCylinderScene();
  else if (name == "occlusion")
    setup = OcclusionScene();
  else {
    std::string list;
    for (const std::string& n : SceneNames()) list += (list.empty() ? "" : ", ") + n;
    throw OptionError("unknown scene '" + name + "' (available: " + list + ")");
  }
  RandomizeTextureOffsets(&setup.scene, seed);
  setup.path.seed = seed;
  return setup;
}

}  // namespace lfrecon::synth
