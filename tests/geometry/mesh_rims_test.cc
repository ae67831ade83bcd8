#include "geometry/mesh_rims.h"

#include <gtest/gtest.h>

#include "geometry/mesh_topology.h"
#include "util/error.h"

namespace lfrecon {
namespace {

// An open n x n grid of unit cells' corners in the z = 0 plane, each cell split
// along its diagonal from (i, j) to (i + 1, j + 1).
TriangleMesh Grid(int n, float spacing = 1, const Eigen::Vector3f& origin = Eigen::Vector3f::Zero()) {
  TriangleMesh m;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) m.vertices.push_back(origin + spacing * Eigen::Vector3f(i, j, 0));
  auto id = [n](int i, int j) { return j * n + i; };
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      m.triangles.emplace_back(id(i, j), id(i + 1, j), id(i + 1, j + 1));
      m.triangles.emplace_back(id(i, j), id(i + 1, j + 1), id(i, j + 1));
    }
  return m;
}

// A closed surface: the six faces of a cube of 2 x 2 cells each would need
// shared corners; an octahedron is closed with 6 vertices.
TriangleMesh Octahedron(const Eigen::Vector3f& centre) {
  TriangleMesh m;
  m.vertices = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  for (auto& v : m.vertices) v += centre;
  m.triangles = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4}, {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  return m;
}

TEST(MeshTopology, OpenEdgesOfAGridAreItsBorder) {
  const int n = 12;
  const TriangleMesh grid = Grid(n);
  int open = 0;
  for (unsigned char mask : OpenEdgeMasks(grid)) open += __builtin_popcount(mask);
  EXPECT_EQ(open, 4 * (n - 1));
  for (unsigned char mask : OpenEdgeMasks(Octahedron(Eigen::Vector3f::Zero()))) EXPECT_EQ(mask, 0);
  const VertexAdjacency adj = BuildVertexAdjacency(grid);
  EXPECT_EQ(adj.Degree(0), 3);          // a corner on the diagonal's side: right, up, diagonal
  EXPECT_EQ(adj.Degree(n + 1), 6);      // an inner vertex
  EXPECT_EQ(adj.Degree(n - 1), 2);      // the other corner
}

TEST(TrimOpenRims, OneRoundDropsTheTrianglesOnTheBorder) {
  const int n = 12;
  TriangleMesh mesh = Grid(n, 0.01f);  // 144 vertices: a large component
  mesh.ComputeVertexNormals();
  const std::size_t before = mesh.triangles.size();
  const RimTrimStats stats = TrimOpenRims(&mesh, RimTrimOptions{});
  // 4 (n - 1) border edges; the corner cells' two triangles each hold two of them.
  EXPECT_EQ(stats.triangles_removed, 4u * (n - 1) - 2);
  EXPECT_EQ(mesh.triangles.size(), before - stats.triangles_removed);
  EXPECT_NEAR(stats.area_removed, stats.triangles_removed * 0.5 * 0.01 * 0.01, 1e-9);
  // Every triangle at the four corners had a border edge: the corners are dropped with them.
  EXPECT_EQ(mesh.vertices.size(), static_cast<std::size_t>(n * n - 4));
  EXPECT_EQ(mesh.normals.size(), mesh.vertices.size());
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) ASSERT_LT(t[k], static_cast<int>(mesh.vertices.size()));
  // A second round takes the next ring.
  TriangleMesh twice = Grid(n, 0.01f);
  RimTrimOptions two;
  two.rounds = 2;
  EXPECT_GT(TrimOpenRims(&twice, two).triangles_removed, stats.triangles_removed + 4u * (n - 3) - 2);
}

TEST(TrimOpenRims, ClosedSurfacesAndSmallComponentsStayWhole) {
  TriangleMesh mesh = Octahedron(Eigen::Vector3f(5, 0, 0));
  mesh.Append(Grid(5));  // 25 vertices: under the default 100
  const TriangleMesh input = mesh;
  const RimTrimStats stats = TrimOpenRims(&mesh, RimTrimOptions{});
  EXPECT_EQ(stats.triangles_removed, 0u);
  EXPECT_EQ(mesh.triangles, input.triangles);
  EXPECT_EQ(mesh.vertices, input.vertices);

  RimTrimOptions every;
  every.min_component_vertices = 0;
  EXPECT_EQ(TrimOpenRims(&mesh, every).triangles_removed, 4u * 4 - 2);  // the grid's border; the octahedron whole
}

TEST(TrimOpenRims, ZeroRoundsChangeNothingAndCheckRejectsNegatives) {
  TriangleMesh mesh = Grid(12);
  const TriangleMesh input = mesh;
  RimTrimOptions none;
  none.rounds = 0;
  EXPECT_EQ(TrimOpenRims(&mesh, none).triangles_removed, 0u);
  EXPECT_EQ(mesh.triangles, input.triangles);
  none.rounds = -1;
  EXPECT_THROW(none.Check(), OptionError);
}

}  // namespace
}  // namespace lfrecon
