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

}  // namespace
}  // namespace lfrecon
