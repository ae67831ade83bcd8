// Dropping small connected components of a mesh.
#include "refine/mesh_cleanup.h"

#include <gtest/gtest.h>

namespace lfrecon {
namespace {

// A unit square (two triangles, area 1) at `offset` scaled by `s`.
void AddSquare(TriangleMesh* m, const Eigen::Vector3f& offset, float s) {
  const int b = static_cast<int>(m->vertices.size());
  for (const Eigen::Vector3f& v : {Eigen::Vector3f(0, 0, 0), Eigen::Vector3f(1, 0, 0), Eigen::Vector3f(1, 1, 0),
                                   Eigen::Vector3f(0, 1, 0)})
    m->vertices.push_back(offset + s * v);
  m->triangles.emplace_back(b, b + 1, b + 2);
  m->triangles.emplace_back(b, b + 2, b + 3);
}

TEST(MeshCleanup, RemovesComponentsBelowTheArea) {
  TriangleMesh m;
  AddSquare(&m, {0, 0, 0}, 1.0f);   // area 1
  AddSquare(&m, {5, 0, 0}, 0.1f);   // area 0.01
  AddSquare(&m, {9, 0, 0}, 0.5f);   // area 0.25
  m.vertices.push_back({20, 20, 20});  // unused
  ComponentFilterStats st;
  const TriangleMesh out = RemoveSmallComponents(m, 0.2, &st);
  EXPECT_EQ(st.components, 3u);
  EXPECT_EQ(st.components_removed, 1u);
  EXPECT_EQ(st.triangles_removed, 2u);
  EXPECT_NEAR(st.area_removed, 0.01, 1e-6);
  ASSERT_EQ(out.triangles.size(), 4u);
  EXPECT_EQ(out.vertices.size(), 8u);
  EXPECT_NEAR(out.SurfaceArea(), 1.25, 1e-5);
  EXPECT_EQ(RemoveSmallComponents(m, 0).triangles.size(), 6u);
  EXPECT_EQ(RemoveSmallComponents(m, 2.0).triangles.size(), 0u);
}

}  // namespace
}  // namespace lfrecon
