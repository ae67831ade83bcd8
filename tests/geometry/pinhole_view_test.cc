#include "geometry/pinhole_view.h"

#include <gtest/gtest.h>

#include <random>

namespace lfrecon {
namespace {

PinholeView MakeView(const Eigen::Vector3d& eye, const Eigen::Vector3d& target) {
  return PinholeView(Camera::PinholeFromHfov(640, 360, 55.0), LookAt(eye, target, Eigen::Vector3d::UnitZ()));
}

TEST(Rigid3, CentreDirectionAndInverse) {
  const Eigen::Vector3d eye(1.0, -0.5, 0.8), target(0, 0, 0.2);
  const Rigid3d pose = LookAt(eye, target, Eigen::Vector3d::UnitZ());
  EXPECT_LT((CameraCenter(pose) - eye).norm(), 1e-12);
  EXPECT_LT((ViewingDirection(pose) - (target - eye).normalized()).norm(), 1e-12);
  EXPECT_LT(((pose * pose.Inverse()) * eye - eye).norm(), 1e-12);
  // Image y points away from world up.
  EXPECT_LT((pose.rotation.inverse() * Eigen::Vector3d::UnitY()).z(), 0.0);
  const Rigid3d round = Rigid3d::FromMatrix(pose.ToMatrix());
  EXPECT_LT((round * eye - pose * eye).norm(), 1e-12);
}

TEST(Rigid3, ViewAngle) {
  const Rigid3d a = LookAt(Eigen::Vector3d(1, 0, 0), Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ());
  const double th = 5.0 * M_PI / 180.0;
  const Rigid3d b =
      LookAt(Eigen::Vector3d(std::cos(th), std::sin(th), 0), Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ());
  EXPECT_NEAR(ViewAngleDeg(a, b), 5.0, 1e-9);
}

TEST(PinholeView, ProjectUnproject) {
  const PinholeView v = MakeView(Eigen::Vector3d(1.2, 0.3, 0.9), Eigen::Vector3d(0, 0, 0.2));
  Eigen::Vector2d p;
  EXPECT_NEAR(v.Project(Eigen::Vector3d(0, 0, 0.2), &p), (Eigen::Vector3d(1.2, 0.3, 0.7)).norm(), 1e-12);
  EXPECT_NEAR(p.x(), 320.0, 1e-9);
  EXPECT_NEAR(p.y(), 180.0, 1e-9);
  const Eigen::Vector3d X = v.Unproject(Eigen::Vector2d(10.5, 300.25), 1.7);
  Eigen::Vector2d q;
  EXPECT_NEAR(v.Project(X, &q), 1.7, 1e-12);
  EXPECT_LT((q - Eigen::Vector2d(10.5, 300.25)).norm(), 1e-9);
  EXPECT_LT((v.RayDirection(q) - (X - v.Center()).normalized()).norm(), 1e-12);
}

TEST(PinholeView, EpipolarLineContainsEveryDepthOfThePixel) {
  const PinholeView a = MakeView(Eigen::Vector3d(1.2, 0.0, 0.9), Eigen::Vector3d(0, 0, 0.2));
  const PinholeView b = MakeView(Eigen::Vector3d(1.19, 0.1, 0.92), Eigen::Vector3d(0.01, 0, 0.2));
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> ux(0, 640), uy(0, 360), ud(0.5, 3.0);
  for (int k = 0; k < 200; ++k) {
    const Eigen::Vector2d p(ux(rng), uy(rng));
    const Eigen::Vector3d l = EpipolarLine(a, b, p);
    EXPECT_NEAR(l.head<2>().norm(), 1.0, 1e-12);
    Eigen::Vector2d q;
    ASSERT_GT(TransferPixel(a, b, p, ud(rng), &q), 0);
    EXPECT_LT(std::abs(l.dot(Eigen::Vector3d(q.x(), q.y(), 1.0))), 1e-8);
  }
}

TEST(PinholeView, FrontoParallelHomographyEqualsPointTransfer) {
  const PinholeView a = MakeView(Eigen::Vector3d(1.2, 0.0, 0.9), Eigen::Vector3d(0, 0, 0.2));
  const PinholeView b = MakeView(Eigen::Vector3d(1.1, 0.3, 0.95), Eigen::Vector3d(0.0, 0.02, 0.2));
  for (double d : {0.6, 1.3, 2.5}) {
    const Eigen::Matrix3d H = FrontoParallelHomography(a, b, d);
    const Eigen::Matrix3d Hinv = H.inverse();
    for (double x = 0.5; x < 640; x += 97.3)
      for (double y = 0.5; y < 360; y += 61.1) {
        Eigen::Vector2d q;
        TransferPixel(a, b, Eigen::Vector2d(x, y), d, &q);
        const Eigen::Vector3d h = H * Eigen::Vector3d(x, y, 1);
        EXPECT_LT((h.head<2>() / h.z() - q).norm(), 1e-8);
        // And back from b to a through the same plane.
        const Eigen::Vector3d back = Hinv * Eigen::Vector3d(q.x(), q.y(), 1);
        EXPECT_LT((back.head<2>() / back.z() - Eigen::Vector2d(x, y)).norm(), 1e-8);
        // The back-mapped point lies on a's plane z = d.
        Eigen::Vector2d p2;
        EXPECT_NEAR(a.Project(a.Unproject(Eigen::Vector2d(x, y), d), &p2), d, 1e-12);
      }
  }
}

TEST(PinholeView, RejectsDistortedCamera) {
  Camera c;
  c.model = CameraModelId::kSimpleRadial;
  c.width = 100;
  c.height = 100;
  c.params = {100, 50, 50, 0.1};
  EXPECT_THROW(PinholeView(c, Rigid3d()), std::invalid_argument);
}

}  // namespace
}  // namespace lfrecon
