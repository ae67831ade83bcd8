// Screened Poisson (Open3D / PoissonRecon) on exact oriented samples of
// analytic shapes: accuracy against the analytic surface, outward normals,
// trimming to V and by distance to the points.
#include "refine/screened_poisson.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "eval/mesh_metrics.h"
#include "fusion/fusion_test_rig.h"
#include "synth/gt_mesh.h"
#include "synth/scene.h"
#include "util/error.h"

namespace lfrecon {
namespace {

// One point per `spacing`² of the sphere's area, uniformly at random, with exact outward normals.
OrientedPoints SphereSamples(const Eigen::Vector3d& c, double r, double spacing, std::uint64_t seed = 3) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g;
  const int n = static_cast<int>(4 * M_PI * r * r / (spacing * spacing));
  OrientedPoints p;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d d = Eigen::Vector3d(g(rng), g(rng), g(rng)).normalized();
    p.points.push_back(c + r * d);
    p.normals.push_back(d);
  }
  return p;
}

TriangleMesh SphereGt(const Eigen::Vector3d& c, double r) {
  synth::Scene s("sphere");
  s.Add(synth::Primitive::Sphere(c, r, synth::Material::Flat({1, 1, 1})).Foreground());
  return synth::GroundTruthMesh(s);
}

MeshMetrics Score(const TriangleMesh& mesh, const TriangleMesh& gt, double tau) {
  MeshMetricsOptions mo;
  mo.thresholds = {tau};
  mo.sample_spacing = tau / 4;
  return EvaluateMesh(mesh, gt, nullptr, mo);
}

TEST(ScreenedPoisson, ExactSphereSamplesGiveF1AboveNinetyFivePercentAtOneVoxel) {
  const double voxel = 0.004, r = 0.1;
  const Eigen::Vector3d c(0.01, -0.02, 0.03);
  const OrientedPoints pts = SphereSamples(c, r, voxel);
  PoissonStats st;
  const TriangleMesh mesh = ScreenedPoissonSurface(pts, voxel, PoissonOptions{}, std::nullopt, &st);
  const MeshMetrics m = Score(mesh, SphereGt(c, r), voxel);
  const MeshMetrics half = Score(mesh, SphereGt(c, r), voxel / 2);
  std::printf("sphere: %zu points, depth %d, %zu triangles (%zu before trimming), %.2f s; F %.4f at 1 voxel, %.4f at "
              "½ voxel\n",
              st.points, st.depth, mesh.triangles.size(), st.triangles_raw, st.seconds, m.scores[0].fscore,
              half.scores[0].fscore);
  EXPECT_GE(m.scores[0].fscore, 0.95);
  EXPECT_GE(half.scores[0].fscore, 0.9);
  // Auto depth: the finest cell is at most a voxel over 1.1 x the points' extent (0.22 m / 4 mm = 55 -> 2^6).
  EXPECT_EQ(st.depth, 6);
  ASSERT_TRUE(mesh.HasNormals());
  double mean_dot = 0;
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i)
    mean_dot += mesh.normals[i].cast<double>().dot((mesh.vertices[i].cast<double>() - c).normalized());
  EXPECT_GT(mean_dot / mesh.vertices.size(), 0.95) << "normals must point outwards";
}

TEST(ScreenedPoisson, TrimsToVolumeAndToThePoints) {
  const double voxel = 0.004, r = 0.1;
  // Half a sphere: Poisson closes it, distance trimming must remove the closing cap.
  OrientedPoints all = SphereSamples(Eigen::Vector3d::Zero(), r, voxel), half;
  for (std::size_t i = 0; i < all.points.size(); ++i)
    if (all.points[i].z() > 0) {
      half.points.push_back(all.points[i]);
      half.normals.push_back(all.normals[i]);
    }
  PoissonOptions o;
  o.density_quantile = 0;
  o.max_point_distance = 0;
  const TriangleMesh closed = ScreenedPoissonSurface(half, voxel, o);
  o.max_point_distance = 2;
  PoissonStats st;
  const TriangleMesh trimmed = ScreenedPoissonSurface(half, voxel, o, std::nullopt, &st);
  Eigen::Vector3f lo, hi;
  closed.Bounds(&lo, &hi);
  EXPECT_LT(lo.z(), -0.02) << "untrimmed Poisson closes the open hemisphere below z = 0";
  trimmed.Bounds(&lo, &hi);
  EXPECT_GT(lo.z(), -3 * voxel);
  EXPECT_GT(st.trimmed_distance, 0u);
  const MeshMetrics m = Score(trimmed, SphereGt(Eigen::Vector3d::Zero(), r), voxel);
  EXPECT_GE(m.scores[0].precision, 0.97);

  // Trimming to V: only the part of the sphere in x >= 0 stays.
  BoundingBox v = testing::Box({0, -1, -1}, {1, 1, 1});
  const TriangleMesh cut = ScreenedPoissonSurface(all, voxel, PoissonOptions{}, v, &st);
  cut.Bounds(&lo, &hi);
  EXPECT_GE(lo.x(), 0.0f);
  EXPECT_GT(st.trimmed_volume, 0u);
  EXPECT_NEAR(cut.SurfaceArea(), 2 * M_PI * r * r, 0.1 * 2 * M_PI * r * r);
}

TEST(ScreenedPoisson, RejectsBadInput) {
  OrientedPoints p = SphereSamples(Eigen::Vector3d::Zero(), 0.1, 0.01);
  p.normals.pop_back();
  EXPECT_THROW(ScreenedPoissonSurface(p, 0.004, PoissonOptions{}), std::invalid_argument);
  PoissonOptions o;
  o.density_quantile = 1.5;
  EXPECT_THROW(ScreenedPoissonSurface(SphereSamples(Eigen::Vector3d::Zero(), 0.1, 0.01), 0.004, o), OptionError);
  EXPECT_THROW(ScreenedPoissonSurface(SphereSamples(Eigen::Vector3d::Zero(), 0.1, 0.01), 0, PoissonOptions{}),
               OptionError);
  // Too few points: an empty mesh, not a crash.
  EXPECT_TRUE(ScreenedPoissonSurface(OrientedPoints{}, 0.004, PoissonOptions{}).triangles.empty());
}

}  // namespace
}  // namespace lfrecon
