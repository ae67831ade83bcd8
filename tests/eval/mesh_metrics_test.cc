// Mesh precision / recall / F-score against analytic shapes with known distances.
#include "eval/mesh_metrics.h"

#include <gtest/gtest.h>

#include <cmath>

#include "synth/gt_mesh.h"
#include "synth/scene.h"
#include "util/error.h"

namespace lfrecon {
namespace {

TriangleMesh SphereMesh(double radius, const Eigen::Vector3d& center = Eigen::Vector3d::Zero()) {
  return synth::TessellatePrimitive(synth::Primitive::Sphere(center, radius, synth::Material::Flat({1, 1, 1})), 5e-5);
}

TriangleMesh RodMesh() {
  return synth::TessellatePrimitive(
      synth::Primitive::Cylinder({0.2, 0, -0.05}, {0.2, 0, 0.05}, 0.002, synth::Material::Flat({1, 1, 1})), 2e-5);
}

// 2 mm spacing: ~30k samples on the 0.1 m sphere, plenty for these checks.
MeshMetricsOptions Fast() {
  MeshMetricsOptions o;
  o.sample_spacing = 0.002;
  return o;
}

BoundingBox Box(double lo, double hi) {
  BoundingBox b;
  b.min = Eigen::Vector3d::Constant(lo);
  b.max = Eigen::Vector3d::Constant(hi);
  return b;
}

TEST(SampleSurface, DensityAndDeterminism) {
  const TriangleMesh m = SphereMesh(0.1);
  const double area = 4 * M_PI * 0.01;
  const auto a = SampleSurface(m, 0.001, 3);
  EXPECT_NEAR(static_cast<double>(a.size()), area / 1e-6, 0.01 * area / 1e-6);
  const auto b = SampleSurface(m, 0.001, 3);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); i += 97) EXPECT_EQ(a[i], b[i]);
  const auto c = SampleSurface(m, 0.001, 4);
  EXPECT_NE(a[0], c[0]);
  for (std::size_t i = 0; i < a.size(); i += 101) EXPECT_NEAR(a[i].norm(), 0.1, 1e-4);
}

TEST(SurfaceDistance, PointToTriangle) {
  TriangleMesh t;
  t.vertices = {{0, 0, 0}, {0.1f, 0, 0}, {0, 0.1f, 0}};
  t.triangles = {{0, 1, 2}};
  const SurfaceDistance d(t, 0.01);
  EXPECT_NEAR(d.Distance({0.02, 0.02, 0.004}), 0.004, 1e-9);       // above the face
  EXPECT_NEAR(d.Distance({-0.003, -0.004, 0.0}), 0.005, 1e-9);     // near a corner
  EXPECT_NEAR(d.Distance({0.05, -0.006, 0.0}), 0.006, 1e-9);       // beside an edge
  EXPECT_TRUE(std::isinf(d.Distance({0.02, 0.02, 0.02})));         // beyond max_distance
}

TEST(EvaluateMesh, IdenticalMeshesScoreOne) {
  const TriangleMesh m = SphereMesh(0.1);
  const MeshMetrics r = EvaluateMesh(m, m, nullptr, Fast());
  ASSERT_EQ(r.scores.size(), 3u);
  for (const ThresholdScore& s : r.scores) {
    EXPECT_DOUBLE_EQ(s.precision, 1.0);
    EXPECT_DOUBLE_EQ(s.recall, 1.0);
    EXPECT_DOUBLE_EQ(s.fscore, 1.0);
    EXPECT_EQ(s.thin_recall, -1);
  }
  EXPECT_LT(r.median_accuracy, 1e-4);
}

TEST(EvaluateMesh, OffsetSurfaceFailsBelowAndPassesAboveItsDistance) {
  const TriangleMesh gt = SphereMesh(0.1), pred = SphereMesh(0.1035);
  const MeshMetrics r = EvaluateMesh(pred, gt, nullptr, Fast());
  EXPECT_EQ(r.Find(0.002)->precision, 0.0);
  EXPECT_EQ(r.Find(0.002)->recall, 0.0);
  EXPECT_EQ(r.Find(0.005)->fscore, 1.0);
  EXPECT_EQ(r.Find(0.010)->fscore, 1.0);
  EXPECT_NEAR(r.median_accuracy, 0.0035, 1e-4);
  EXPECT_NEAR(r.median_completeness, 0.0035, 1e-4);
}

TEST(EvaluateMesh, PartialReconstructionLosesRecallOnly) {
  const TriangleMesh gt = SphereMesh(0.1);
  TriangleMesh half = gt;
  half.triangles.clear();
  for (const Eigen::Vector3i& t : gt.triangles)
    if (gt.vertices[t[0]].z() > 0.03f && gt.vertices[t[1]].z() > 0.03f && gt.vertices[t[2]].z() > 0.03f)
      half.triangles.push_back(t);
  const MeshMetrics r = EvaluateMesh(half, gt, nullptr, Fast());
  // Recall at τ: the cap's share of the area (~35 %) plus the band of the
  // sphere within τ of its rim (height τ·sin θ at z = 0.03, θ the polar angle).
  const double cap = half.SurfaceArea() / gt.SurfaceArea();
  const double sin_theta = std::sqrt(1 - 0.3 * 0.3);
  EXPECT_NEAR(cap, 0.35, 0.01);
  EXPECT_DOUBLE_EQ(r.Find(0.002)->precision, 1.0);
  EXPECT_NEAR(r.Find(0.002)->recall, cap + 0.002 * sin_theta / 0.2, 0.005);
  EXPECT_NEAR(r.Find(0.010)->recall, cap + 0.010 * sin_theta / 0.2, 0.005);
}

TEST(EvaluateMesh, PredictionsOutsideVolumeAreIgnored) {
  const TriangleMesh gt = SphereMesh(0.1);
  TriangleMesh pred = gt;
  pred.Append(SphereMesh(0.05, {0.5, 0, 0}));  // clutter outside V, a quarter of the area
  MeshMetricsOptions o = Fast();
  const MeshMetrics loose = EvaluateMesh(pred, gt, nullptr, o);
  EXPECT_NEAR(loose.Find(0.005)->precision, 0.8, 0.01);
  o.volume = Box(-0.2, 0.2);
  const MeshMetrics strict = EvaluateMesh(pred, gt, nullptr, o);
  EXPECT_DOUBLE_EQ(strict.Find(0.005)->precision, 1.0);
  EXPECT_GT(strict.predicted_samples_outside, 0u);
}

TEST(EvaluateMesh, ThinRecall) {
  TriangleMesh gt = SphereMesh(0.1);
  const TriangleMesh rod = RodMesh();
  gt.Append(rod);
  const TriangleMesh without_rod = SphereMesh(0.1);
  const MeshMetrics r0 = EvaluateMesh(without_rod, gt, &rod, Fast());
  EXPECT_EQ(r0.Find(0.002)->thin_recall, 0.0);
  EXPECT_GT(r0.Find(0.002)->recall, 0.95);  // the rod is a small part of the area
  const MeshMetrics r1 = EvaluateMesh(gt, gt, &rod, Fast());
  EXPECT_DOUBLE_EQ(r1.Find(0.002)->thin_recall, 1.0);
  EXPECT_GT(r1.thin_samples, 250u);  // 12.6 cm² of rod at one sample per 4 mm²
}

TEST(EvaluateMesh, EmptyPredictionAndBadOptions) {
  const TriangleMesh gt = SphereMesh(0.1);
  const MeshMetrics r = EvaluateMesh(TriangleMesh{}, gt, nullptr, Fast());
  EXPECT_EQ(r.Find(0.01)->fscore, 0.0);
  MeshMetricsOptions o;
  o.thresholds.clear();
  EXPECT_THROW(EvaluateMesh(gt, gt, nullptr, o), OptionError);
  o.thresholds = {0.002};
  o.sample_spacing = 0;
  EXPECT_THROW(EvaluateMesh(gt, gt, nullptr, o), OptionError);
}

}  // namespace
}  // namespace lfrecon
