// The generated marching-cubes tables: every case uses exactly its crossing
// edges, and cells put together give closed, consistently oriented surfaces,
// also across ambiguous faces.
#include "fusion/marching_cubes_table.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <map>
#include <random>
#include <set>

namespace lfrecon {
namespace {

TEST(MarchingCubesTable, EachCaseUsesExactlyItsCrossingEdges) {
  const auto& edges = mc::Edges();
  for (int mask = 0; mask < 256; ++mask) {
    std::set<int> crossing, used;
    for (int e = 0; e < 12; ++e)
      if (((mask >> edges[e].corner0) & 1) != ((mask >> edges[e].corner1) & 1)) crossing.insert(e);
    for (const auto& t : mc::Triangles(mask))
      for (int e : t) used.insert(e);
    EXPECT_EQ(used, crossing) << "mask " << mask;
  }
  EXPECT_TRUE(mc::Triangles(0).empty());
  EXPECT_TRUE(mc::Triangles(255).empty());
}

// Random inside/outside fields on a grid whose border is outside: the
// surface must be closed, every edge shared by two triangles in opposite
// directions, and wound outwards (positive enclosed volume).
TEST(MarchingCubesTable, RandomFieldsGiveClosedOutwardSurfaces) {
  const auto& edges = mc::Edges();
  std::mt19937 rng(3);
  const int n = 7;
  for (int trial = 0; trial < 50; ++trial) {
    std::vector<int> inside(n * n * n, 0);
    auto at = [&](int i, int j, int k) -> int& { return inside[(k * n + j) * n + i]; };
    for (int k = 1; k < n - 1; ++k)
      for (int j = 1; j < n - 1; ++j)
        for (int i = 1; i < n - 1; ++i) at(i, j, k) = (rng() % 100) < 45;
    std::map<std::tuple<int, int, int, int>, int> ids;
    std::vector<Eigen::Vector3d> verts;
    std::vector<std::array<int, 3>> tris;
    for (int k = 0; k + 1 < n; ++k)
      for (int j = 0; j + 1 < n; ++j)
        for (int i = 0; i + 1 < n; ++i) {
          int mask = 0;
          for (int c = 0; c < 8; ++c) mask |= at(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1)) << c;
          for (const auto& t : mc::Triangles(mask)) {
            std::array<int, 3> tri;
            for (int q = 0; q < 3; ++q) {
              const mc::Edge& e = edges[t[q]];
              const int c = e.corner0;
              const auto key = std::make_tuple(i + (c & 1), j + ((c >> 1) & 1), k + ((c >> 2) & 1), e.axis);
              auto [it, fresh] = ids.emplace(key, static_cast<int>(verts.size()));
              if (fresh) {
                Eigen::Vector3d p(std::get<0>(key), std::get<1>(key), std::get<2>(key));
                p[e.axis] += 0.5;
                verts.push_back(p);
              }
              tri[q] = it->second;
            }
            tris.push_back(tri);
          }
        }
    std::map<std::pair<int, int>, int> directed;
    double volume = 0;
    for (const auto& t : tris) {
      for (int q = 0; q < 3; ++q) directed[{t[q], t[(q + 1) % 3]}]++;
      volume += verts[t[0]].dot(verts[t[1]].cross(verts[t[2]])) / 6.0;
    }
    int bad = 0;
    for (const auto& [e, count] : directed) {
      const auto rev = directed.find({e.second, e.first});
      bad += count != 1 || rev == directed.end() || rev->second != 1;
    }
    EXPECT_EQ(bad, 0) << "trial " << trial;
    // Each inside voxel contributes about one cell of volume; outward winding makes it positive.
    EXPECT_GT(volume, 0) << "trial " << trial;
  }
}

}  // namespace
}  // namespace lfrecon
