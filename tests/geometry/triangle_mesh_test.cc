#include "geometry/triangle_mesh.h"

#include <gtest/gtest.h>

#include <vector>

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

TEST(BoundingBox, RayBoxInterval) {
  BoundingBox box;
  box.min = Eigen::Vector3d(-1, -1, 4);
  box.max = Eigen::Vector3d(1, 1, 6);
  const Eigen::Vector3d o = Eigen::Vector3d::Zero();
  double t0 = 0, t1 = 0;
  ASSERT_TRUE(RayBoxInterval(o, Eigen::Vector3d(0, 0, 2), box, &t0, &t1));
  EXPECT_DOUBLE_EQ(t0, 2.0);
  EXPECT_DOUBLE_EQ(t1, 3.0);
  // Through the side: enters at z = 4, leaves at x = 1, z = 1 / 0.19.
  ASSERT_TRUE(RayBoxInterval(o, Eigen::Vector3d(0.19, 0, 1), box, &t0, &t1));
  EXPECT_DOUBLE_EQ(t0, 4.0);
  EXPECT_NEAR(t1, 1 / 0.19, 1e-12);
  // Starting inside: from 0.
  ASSERT_TRUE(RayBoxInterval(Eigen::Vector3d(0, 0, 5), Eigen::Vector3d(1, 0, 0), box, &t0, &t1));
  EXPECT_EQ(t0, 0.0);
  EXPECT_DOUBLE_EQ(t1, 1.0);
  EXPECT_FALSE(RayBoxInterval(o, Eigen::Vector3d(0.3, 0, 1), box, &t0, &t1));
  EXPECT_GT(t0, t1);
  EXPECT_FALSE(RayBoxInterval(o, Eigen::Vector3d(0, 0, -1), box, &t0, &t1));
  EXPECT_GT(t0, t1);
  EXPECT_FALSE(RayBoxInterval(Eigen::Vector3d(2, 0, 0), Eigen::Vector3d(0, 0, 1), box, &t0, &t1));  // parallel, beside
  EXPECT_GT(t0, t1);
}

TEST(TriangleMesh, RemoveUnreferencedVerticesKeepsTheOthersInOrder) {
  TriangleMesh m;
  for (int i = 0; i < 6; ++i) {
    m.vertices.emplace_back(i, 0, 0);
    m.normals.emplace_back(0, 0, 1);
    m.colors.emplace_back(i, 0, 0);
  }
  m.triangles = {{4, 1, 3}, {3, 1, 5}};  // 0 and 2 unused
  m.RemoveUnreferencedVertices();
  ASSERT_EQ(m.vertices.size(), 4u);
  EXPECT_EQ(m.normals.size(), 4u);
  ASSERT_EQ(m.colors.size(), 4u);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(m.colors[i][0], std::vector<int>({1, 3, 4, 5})[i]);
  EXPECT_EQ(m.triangles[0], Eigen::Vector3i(2, 0, 1));
  EXPECT_EQ(m.triangles[1], Eigen::Vector3i(1, 0, 3));
  EXPECT_EQ(m.vertices[2].x(), 4.0f);
}

}  // namespace
}  // namespace lfrecon
