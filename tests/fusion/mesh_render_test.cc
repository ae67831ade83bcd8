// Turntable renders: a sphere centred in V must appear as a disc of the
// predicted size, in its own colour, in every tile.
#include "fusion/mesh_render.h"

#include <gtest/gtest.h>

#include <cmath>

#include "fusion_test_rig.h"
#include "synth/gt_mesh.h"
#include "util/error.h"

namespace lfrecon {
namespace {

TEST(RenderTurntable, SphereIsADiscOfThePredictedSizeInEachTile) {
  synth::Scene scene("s");
  const BoundingBox V = testing::Box(Eigen::Vector3d::Constant(-0.2), Eigen::Vector3d::Constant(0.2));
  scene.set_foreground_bbox(V);
  const double radius = 0.1;
  scene.Add(synth::Primitive::Sphere(Eigen::Vector3d::Zero(), radius, synth::Material::Flat({1, 0, 0})).Foreground());
  TriangleMesh mesh = synth::GroundTruthMesh(scene);
  mesh.colors.assign(mesh.vertices.size(), Color3u8(200, 40, 40));
  TurntableOptions o;
  o.views = 3;
  o.tile_size = 200;
  const cv::Mat img = RenderTurntable(mesh, V, o);
  ASSERT_EQ(img.type(), CV_8UC3);
  ASSERT_EQ(img.cols, 600);
  ASSERT_EQ(img.rows, 200);
  // The camera frames V's bounding sphere (radius sqrt(3)*0.2) at hfov 40°, 5 % margin.
  const double half = 20 * M_PI / 180;
  const double dist = std::sqrt(3.0) * 0.2 / std::sin(half) * 1.05;
  const double f = 100 / std::tan(half);
  // Apparent radius of a sphere of radius r at distance d: f * tan(asin(r / d)).
  const double disc_r = f * std::tan(std::asin(radius / dist));
  const double expected_area = M_PI * disc_r * disc_r;
  for (int k = 0; k < 3; ++k) {
    const cv::Mat tile = img(cv::Rect(k * 200, 0, 200, 200));
    int covered = 0, reddish = 0;
    double cx = 0, cy = 0;
    for (int r = 0; r < 200; ++r)
      for (int c = 0; c < 200; ++c) {
        const cv::Vec3b p = tile.at<cv::Vec3b>(r, c);
        if (p == cv::Vec3b(255, 255, 255)) continue;
        ++covered;
        cx += c + 0.5;
        cy += r + 0.5;
        reddish += p[2] > 2 * p[1] && p[2] > 2 * p[0];  // BGR
      }
    EXPECT_NEAR(covered, expected_area, 0.05 * expected_area) << "tile " << k;
    EXPECT_EQ(reddish, covered) << "tile " << k;
    EXPECT_NEAR(cx / covered, 100, 1.0);
    EXPECT_NEAR(cy / covered, 100, 1.0);
  }
}

TEST(RenderTurntable, EmptyMeshIsWhiteAndBadOptionsThrow) {
  const BoundingBox V = testing::Box(Eigen::Vector3d::Constant(-1), Eigen::Vector3d::Constant(1));
  const cv::Mat img = RenderTurntable(TriangleMesh(), V);
  EXPECT_EQ(cv::countNonZero(img.reshape(1) != 255), 0);
  TurntableOptions o;
  o.views = 0;
  EXPECT_THROW(RenderTurntable(TriangleMesh(), V, o), OptionError);
}

}  // namespace
}  // namespace lfrecon
