#include "geometry/mesh_smoothing.h"

#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <random>
#include <utility>

#include "util/error.h"

namespace lfrecon {
namespace {

// A unit icosphere: the icosahedron with each triangle split in four `levels` times.
TriangleMesh UnitIcosphere(int levels) {
  const float t = (1.0f + std::sqrt(5.0f)) / 2.0f;
  TriangleMesh m;
  m.vertices = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  m.triangles = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
                 {11, 10, 2}, {10, 7, 6}, {7, 1, 8},   {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
                 {3, 8, 9},  {4, 9, 5},  {2, 4, 11},  {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (auto& v : m.vertices) v.normalize();
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<int, int>, int> midpoint;
    auto mid = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      auto it = midpoint.find(key);
      if (it != midpoint.end()) return it->second;
      m.vertices.push_back((m.vertices[a] + m.vertices[b]).normalized());
      return midpoint[key] = static_cast<int>(m.vertices.size()) - 1;
    };
    std::vector<Eigen::Vector3i> split;
    for (const auto& tri : m.triangles) {
      const int ab = mid(tri[0], tri[1]), bc = mid(tri[1], tri[2]), ca = mid(tri[2], tri[0]);
      split.insert(split.end(), {{tri[0], ab, ca}, {tri[1], bc, ab}, {tri[2], ca, bc}, {ab, bc, ca}});
    }
    m.triangles = std::move(split);
  }
  return m;
}

// Radial noise of standard deviation `sigma` (deterministic).
void AddRadialNoise(TriangleMesh* m, float sigma) {
  std::mt19937 rng(7);
  std::normal_distribution<float> noise(0, sigma);
  for (auto& v : m->vertices) v *= 1 + noise(rng);
}

double RmsRadiusError(const TriangleMesh& m) {
  double s = 0;
  for (const auto& v : m.vertices) s += std::pow(v.norm() - 1.0, 2);
  return std::sqrt(s / m.vertices.size());
}

double MeanRadius(const TriangleMesh& m) {
  double s = 0;
  for (const auto& v : m.vertices) s += v.norm();
  return s / m.vertices.size();
}

TEST(SmoothTaubin, RemovesNoiseWithoutShrinking) {
  TriangleMesh sphere = UnitIcosphere(4);  // 2562 vertices, ~0.06 apart
  AddRadialNoise(&sphere, 0.02f);
  const double rms_before = RmsRadiusError(sphere);
  ASSERT_NEAR(rms_before, 0.02, 0.002);
  TaubinSmoothingOptions options;
  const TaubinSmoothingStats stats = SmoothTaubin(&sphere, options);
  EXPECT_EQ(stats.vertices_moved, sphere.vertices.size());
  const double rms_after = RmsRadiusError(sphere);  // 0.0199 -> 0.0083 when written
  EXPECT_LT(rms_after, rms_before / 2) << rms_before << " -> " << rms_after;
  // λ|μ keeps the sphere's size: plain Laplacian steps (μ = 0 here) would shrink it.
  EXPECT_NEAR(MeanRadius(sphere), 1.0, 0.005);
}

TEST(SmoothTaubin, NoVertexMovesFartherThanTheBound) {
  TriangleMesh sphere = UnitIcosphere(3);
  AddRadialNoise(&sphere, 0.05f);
  const TriangleMesh input = sphere;
  TaubinSmoothingOptions options;
  options.max_displacement = 0.01;
  const TaubinSmoothingStats stats = SmoothTaubin(&sphere, options);
  double max_moved = 0;
  for (std::size_t i = 0; i < input.vertices.size(); ++i)
    max_moved = std::max<double>(max_moved, (sphere.vertices[i] - input.vertices[i]).norm());
  EXPECT_LE(max_moved, 0.01 + 1e-6);
  EXPECT_GT(max_moved, 0.009);  // the noise is larger than the bound: it binds
  EXPECT_GT(stats.vertices_capped, 0u);
}

TEST(SmoothTaubin, SmallComponentsStayAsTheyAre) {
  TriangleMesh mesh = UnitIcosphere(3);  // 642 vertices
  AddRadialNoise(&mesh, 0.02f);
  TriangleMesh fragment = UnitIcosphere(1);  // 42 vertices: under the default 100
  for (auto& v : fragment.vertices) v = 0.05f * v + Eigen::Vector3f(3, 0, 0);
  AddRadialNoise(&fragment, 0.1f);
  const std::size_t first_fragment_vertex = mesh.vertices.size();
  mesh.Append(fragment);
  const TriangleMesh input = mesh;
  const TaubinSmoothingStats stats = SmoothTaubin(&mesh, TaubinSmoothingOptions{});
  EXPECT_EQ(stats.vertices_moved, first_fragment_vertex);
  for (std::size_t i = first_fragment_vertex; i < mesh.vertices.size(); ++i)
    EXPECT_EQ(mesh.vertices[i], input.vertices[i]) << i;
  EXPECT_NE(mesh.vertices[0], input.vertices[0]);
}

TEST(SmoothTaubin, ZeroIterationsChangeNothing) {
  TriangleMesh sphere = UnitIcosphere(2);
  AddRadialNoise(&sphere, 0.02f);
  const TriangleMesh input = sphere;
  TaubinSmoothingOptions options;
  options.iterations = 0;
  SmoothTaubin(&sphere, options);
  EXPECT_EQ(sphere.vertices, input.vertices);
}

TEST(SmoothTaubin, CheckRejectsAShrinkingPair) {
  TaubinSmoothingOptions options;
  options.mu = -0.4;  // |μ| < λ: every pair shrinks
  EXPECT_THROW(options.Check(), OptionError);
  options = TaubinSmoothingOptions{};
  options.max_displacement = 0;
  EXPECT_THROW(options.Check(), OptionError);
}

}  // namespace
}  // namespace lfrecon
