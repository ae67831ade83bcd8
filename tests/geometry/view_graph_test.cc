#include "geometry/view_graph.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "geometry/rigid3.h"

namespace lfrecon {
namespace {

std::vector<Eigen::Vector3d> HelixDirections(int n, double loops, double jitter_deg, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> jitter(0.0, jitter_deg * M_PI / 180.0);
  std::vector<Eigen::Vector3d> dirs;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * M_PI * loops * i / n;
    const double h = 0.3 + 0.8 * i / n;
    Eigen::Vector3d eye(std::cos(a), std::sin(a), h);
    Rigid3d pose = LookAt(eye, Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ());
    const Eigen::Quaterniond noise = Eigen::AngleAxisd(jitter(rng), Eigen::Vector3d::UnitX()) *
                                     Eigen::AngleAxisd(jitter(rng), Eigen::Vector3d::UnitY());
    pose.rotation = noise * pose.rotation;
    dirs.push_back(ViewingDirection(pose));
  }
  return dirs;
}

TEST(ViewGraph, MatchesBruteForceOnHelixWithJitter) {
  for (double angle : {5.0, 15.0}) {
    const auto dirs = HelixDirections(1500, 3.0, 0.5, 11);
    const ViewGraph graph(dirs, angle);
    const auto brute = ViewGraph::BruteForce(dirs, angle);
    ASSERT_EQ(graph.num_views(), 1500);
    size_t total = 0;
    for (int i = 0; i < graph.num_views(); ++i) {
      EXPECT_EQ(graph.Neighbors(i), brute[i]) << "view " << i;
      total += brute[i].size();
      for (int j : graph.Neighbors(i)) EXPECT_LE(graph.AngleDeg(i, j), angle);
    }
    // Three loops: neighbours come from other loops too, not only the sequence.
    EXPECT_GT(total, 1500u * 10u);
  }
}

TEST(ViewGraph, RandomDirectionsAndDuplicates) {
  std::mt19937 rng(5);
  std::normal_distribution<double> g(0, 1);
  std::vector<Eigen::Vector3d> dirs;
  for (int i = 0; i < 800; ++i) dirs.push_back(Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized());
  dirs.push_back(dirs[0]);  // coincident cameras
  const ViewGraph graph(dirs, 10.0);
  const auto brute = ViewGraph::BruteForce(dirs, 10.0);
  for (int i = 0; i < graph.num_views(); ++i) EXPECT_EQ(graph.Neighbors(i), brute[i]);
  EXPECT_EQ(graph.Neighbors(800).front(), 0);
}

TEST(ViewGraph, MaxIndexGapCutsTheSeamOfAClosedLoop) {
  // One flat loop of 100 views, 3.6° apart: within 10°, views 0 and 99 are neighbours.
  std::vector<Eigen::Vector3d> dirs;
  for (int i = 0; i < 100; ++i) {
    const double a = 2 * M_PI * i / 100;
    dirs.emplace_back(std::cos(a), std::sin(a), 0.0);
  }
  const ViewGraph all(dirs, 10.0), cut(dirs, 10.0, 50);
  auto has = [](const std::vector<int>& v, int j) { return std::find(v.begin(), v.end(), j) != v.end(); };
  EXPECT_TRUE(has(all.Neighbors(0), 99));
  EXPECT_TRUE(has(all.Neighbors(0), 98));
  EXPECT_FALSE(has(cut.Neighbors(0), 99));
  EXPECT_EQ(cut.Neighbors(0), (std::vector<int>{1, 2}));
  EXPECT_EQ(cut.Neighbors(50), all.Neighbors(50));  // away from the seam nothing changes
}

TEST(ViewGraph, SortedByAngle) {
  const auto dirs = HelixDirections(480, 1.0, 0.0, 1);
  const ViewGraph graph(dirs, 5.0);
  for (int i = 0; i < graph.num_views(); ++i) {
    const auto& n = graph.Neighbors(i);
    for (size_t k = 1; k < n.size(); ++k) EXPECT_LE(graph.AngleDeg(i, n[k - 1]), graph.AngleDeg(i, n[k]) + 1e-12);
  }
}

std::vector<Eigen::Vector3d> CircleDirections(int n, double step_deg) {
  std::vector<Eigen::Vector3d> dirs;
  for (int i = 0; i < n; ++i) {
    const double a = i * step_deg * M_PI / 180.0;
    dirs.emplace_back(std::cos(a), std::sin(a), 0.0);
  }
  return dirs;
}

TEST(AngleBetweenDeg, TinyAnglesAndAnyLength) {
  const Eigen::Vector3d a(1, 0, 0);
  for (double deg : {1e-6, 1e-3, 0.12, 30.0, 179.0}) {
    const double r = deg * M_PI / 180.0;
    const Eigen::Vector3d b(std::cos(r), std::sin(r), 0);
    EXPECT_NEAR(AngleBetweenDeg(a, b), deg, 1e-9 * std::max(1.0, deg)) << deg;
    EXPECT_NEAR(AngleBetweenDeg(3.0 * a, 0.5 * b), deg, 1e-9 * std::max(1.0, deg)) << deg;
  }
  EXPECT_EQ(AngleBetweenDeg(a, a), 0.0);
  EXPECT_NEAR(AngleBetweenDeg(a, -a), 180.0, 1e-12);
}

TEST(SpacedAtLeast, GreedyAlongTheSequence) {
  // 0.3° apart, at least 1°: every fourth (1.2°), from the first.
  const std::vector<char> kept = SpacedAtLeast(CircleDirections(13, 0.3), 1.0);
  std::vector<int> idx;
  for (int k = 0; k < 13; ++k)
    if (kept[k]) idx.push_back(k);
  EXPECT_EQ(idx, (std::vector<int>{0, 4, 8, 12}));
  // Spaced exactly the step apart: every entry, rounding notwithstanding.
  for (double step : {0.12, 0.5, 0.75}) {
    const std::vector<char> all = SpacedAtLeast(CircleDirections(200, step), step);
    EXPECT_EQ(std::count(all.begin(), all.end(), 1), 200) << step;
  }
  // No step: everything; no directions: nothing.
  const std::vector<char> none = SpacedAtLeast(CircleDirections(5, 0.1), 0.0);
  EXPECT_EQ(std::count(none.begin(), none.end(), 1), 5);
  EXPECT_TRUE(SpacedAtLeast({}, 1.0).empty());
  // Measured from the last kept entry, not the previous one: an uneven path.
  std::vector<Eigen::Vector3d> uneven = CircleDirections(1, 0);
  for (double deg : {0.6, 1.1, 1.5, 2.2, 2.3, 3.3}) uneven.emplace_back(std::cos(deg * M_PI / 180), std::sin(deg * M_PI / 180), 0);
  const std::vector<char> u = SpacedAtLeast(uneven, 1.0);
  EXPECT_EQ(std::vector<char>(u.begin(), u.end()), (std::vector<char>{1, 0, 1, 0, 1, 0, 1}));
}

}  // namespace
}  // namespace lfrecon
