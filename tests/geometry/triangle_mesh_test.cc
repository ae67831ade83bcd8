#include "geometry/triangle_mesh.h"

#include <gtest/gtest.h>

namespace lfrecon {
namespace {

TEST(BoundingBox, RayMeetsBox) {
  BoundingBox box;
  box.min = Eigen::Vector3d(-1, -1, 4);
  box.max = Eigen::Vector3d(1, 1, 6);
  const Eigen::Vector3d o = Eigen::Vector3d::Zero();
  EXPECT_TRUE(RayMeetsBox(o, Eigen::Vector3d(0, 0, 1), box));
  EXPECT_TRUE(RayMeetsBox(o, Eigen::Vector3d(0.19, 0, 1), box));  // x = 0.76 at z = 4, 1.14 at z = 6: through the side
  EXPECT_FALSE(RayMeetsBox(o, Eigen::Vector3d(0.3, 0, 1), box));  // x = 1.2 already at z = 4
  EXPECT_FALSE(RayMeetsBox(o, Eigen::Vector3d(0, 0, -1), box));   // behind the origin
  EXPECT_TRUE(RayMeetsBox(Eigen::Vector3d(0, 0, 5), Eigen::Vector3d(1, 0, 0), box));  // starts inside
  EXPECT_TRUE(RayMeetsBox(o, Eigen::Vector3d(0.3, 0, 1), box.Grown(0.3)));             // x = 1.2 <= 1.3 at z = 4
}

}  // namespace
}  // namespace lfrecon
