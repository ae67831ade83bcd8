#include "synth/camera_path.h"

#include <gtest/gtest.h>

#include <cmath>

#include "geometry/pinhole_view.h"
#include "util/error.h"

namespace lfrecon::synth {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

CameraPathOptions Base(PathType type, int frames) {
  CameraPathOptions o;
  o.type = type;
  o.num_frames = frames;
  o.target = Vector3d(0.01, -0.02, 0.21);
  o.radius = 0.9;
  o.height = 0.95;
  return o;
}

TEST(CameraPath, CircleLooksAtTargetWithDenseSteps) {
  const CameraPathOptions o = Base(PathType::kCircle, 480);
  const std::vector<Rigid3d> poses = MakeCameraPath(o);
  ASSERT_EQ(poses.size(), 480u);
  EXPECT_NEAR(o.StepDeg(), 0.75, 1e-12);
  const Camera cam = Camera::PinholeFromHfov(640, 360, 55);
  double max_angle = 0;
  for (int i = 0; i < 480; ++i) {
    const Vector3d c = CameraCenter(poses[i]);
    EXPECT_NEAR(c.z(), 0.95, 1e-12);
    EXPECT_NEAR((c - o.target).head<2>().norm(), 0.9, 1e-12);
    const double az = std::atan2(c.y() - o.target.y(), c.x() - o.target.x()) * 180 / M_PI;
    EXPECT_NEAR(std::remainder(az - 0.75 * i, 360.0), 0.0, 1e-9);
    Vector2d p;
    EXPECT_GT(PinholeView(cam, poses[i]).Project(o.target, &p), 0);
    EXPECT_NEAR(p.x(), 320.0, 1e-9);
    EXPECT_NEAR(p.y(), 180.0, 1e-9);
    // World up appears as image "up" (negative y).
    EXPECT_LT((poses[i].rotation * Vector3d::UnitZ()).y(), 0.0);
    max_angle = std::max(max_angle, ViewAngleDeg(poses[i], poses[(i + 1) % 480]));
  }
  // The viewing direction turns by less than the azimuth step when looking down.
  EXPECT_LE(max_angle, 0.75 + 1e-9);
  EXPECT_GT(max_angle, 0.5);
}

TEST(CameraPath, HelixRisesOverSeveralLoops) {
  CameraPathOptions o = Base(PathType::kHelix, 300);
  o.loops = 3;
  o.helix_rise = 0.4;
  const std::vector<Rigid3d> poses = MakeCameraPath(o);
  EXPECT_NEAR(CameraCenter(poses.front()).z(), 0.75, 1e-12);
  EXPECT_NEAR(CameraCenter(poses.back()).z(), 1.15, 1e-12);
  for (int i = 1; i < 300; ++i) EXPECT_GT(CameraCenter(poses[i]).z(), CameraCenter(poses[i - 1]).z());
  // Frames 100 apart are one full turn apart in azimuth.
  const Vector3d a = CameraCenter(poses[10]) - o.target, b = CameraCenter(poses[110]) - o.target;
  EXPECT_NEAR(std::atan2(a.y(), a.x()), std::atan2(b.y(), b.x()), 1e-9);
}

TEST(CameraPath, HandheldIsSmoothBoundedAndSeeded) {
  CameraPathOptions o = Base(PathType::kHandheld, 480);
  CameraPathOptions circle = o;
  circle.type = PathType::kCircle;
  const std::vector<Rigid3d> h = MakeCameraPath(o), c = MakeCameraPath(circle);
  double max_dev = 0, max_rot = 0, max_second = 0, max_step_angle = 0;
  for (int i = 0; i < 480; ++i) {
    max_dev = std::max(max_dev, (CameraCenter(h[i]) - CameraCenter(c[i])).cwiseAbs().maxCoeff());
    max_rot = std::max(max_rot, ViewAngleDeg(h[i], c[i]));
    if (i > 0 && i + 1 < 480) {
      const Vector3d second = CameraCenter(h[i + 1]) - 2 * CameraCenter(h[i]) + CameraCenter(h[i - 1]);
      max_second = std::max(max_second, second.norm());
    }
    if (i + 1 < 480) max_step_angle = std::max(max_step_angle, ViewAngleDeg(h[i], h[i + 1]));
  }
  EXPECT_GT(max_dev, 0.3 * o.jitter_position);          // it does wobble
  EXPECT_LE(max_dev, 1.05 * o.jitter_position + 1e-3);  // ... within its amplitude (plus look-at change)
  EXPECT_GT(max_rot, 0.2);
  EXPECT_LT(max_rot, 3.0);
  // Smooth: accelerations are tiny compared with the 0.75-degree (~12 mm) step.
  EXPECT_LT(max_second, 1e-3);
  EXPECT_LT(max_step_angle, 1.2);
  // Deterministic per seed; another seed wobbles differently.
  EXPECT_EQ(CameraPathPose(o, 123).translation, h[123].translation);
  o.seed = 99;
  EXPECT_GT((CameraCenter(CameraPathPose(o, 123)) - CameraCenter(h[123])).norm(), 1e-4);
}

TEST(CameraPath, NamesAndChecks) {
  EXPECT_EQ(PathTypeFromName("helix"), PathType::kHelix);
  EXPECT_EQ(PathTypeName(PathType::kHandheld), "handheld");
  EXPECT_THROW(PathTypeFromName("spiral"), OptionError);
  CameraPathOptions o;
  o.num_frames = 0;
  EXPECT_THROW(MakeCameraPath(o), OptionError);
}

}  // namespace
}  // namespace lfrecon::synth
