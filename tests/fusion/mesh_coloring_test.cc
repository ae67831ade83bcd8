// Vertex colours from frames, and the mesh z-buffer they rely on.
#include "fusion/mesh_coloring.h"

#include <gtest/gtest.h>

#include <algorithm>

#include "fusion_test_rig.h"
#include "synth/gt_mesh.h"
#include "util/error.h"

namespace lfrecon {
namespace {

TEST(RenderMeshDepth, MatchesRayCastDepth) {
  synth::Scene scene("s");
  scene.set_foreground_bbox(testing::Box(Eigen::Vector3d::Constant(-0.2), Eigen::Vector3d::Constant(0.2)));
  scene.Add(synth::Primitive::Sphere(Eigen::Vector3d::Zero(), 0.1, synth::Material::Flat({1, 0, 0})).Foreground());
  testing::AddDome(&scene);
  const PinholeView view = testing::LookAtView({0.5, 0.1, 0.2}, {0, 0, 0}, 160, 90, 40);
  const DepthMap exact = testing::ExactDepth(scene, view);
  const cv::Mat rendered = RenderMeshDepth(synth::GroundTruthMesh(scene), view);
  int compared = 0, covered_wrongly = 0;
  std::vector<double> errors;
  for (int r = 0; r < view.height; ++r)
    for (int c = 0; c < view.width; ++c) {
      const bool fg = exact.label.at<std::uint8_t>(r, c) == static_cast<std::uint8_t>(DepthLabel::kForeground);
      const float d = rendered.at<float>(r, c);
      if (fg && d > 0) {
        errors.push_back(std::abs(static_cast<double>(d) - exact.depth.at<float>(r, c)));
        ++compared;
      } else if (!fg && d > 0) {
        ++covered_wrongly;
      }
    }
  EXPECT_GT(compared, 1000);
  // The tessellation's chord error (5e-5 m) grows to millimetres only at grazing silhouette pixels.
  std::sort(errors.begin(), errors.end());
  EXPECT_LT(errors[errors.size() / 2], 5e-5);
  EXPECT_LT(errors[errors.size() * 95 / 100], 5e-4);
  EXPECT_LT(covered_wrongly, 40);  // at most the silhouette's pixels
}

TEST(ColorizeMesh, TakesTheColourOfTheViewsThatSeeEachVertex) {
  // Two flat-coloured spheres; each vertex must take its own sphere's colour,
  // never its neighbour's (visibility), and hidden vertices stay grey.
  synth::Scene scene("two");
  scene.set_foreground_bbox(testing::Box(Eigen::Vector3d::Constant(-0.3), Eigen::Vector3d::Constant(0.3)));
  scene.Add(synth::Primitive::Sphere({-0.1, 0, 0}, 0.07, synth::Material::Flat({1.0f, 0.2f, 0.1f})).Foreground());
  scene.Add(synth::Primitive::Sphere({0.1, 0, 0}, 0.07, synth::Material::Flat({0.1f, 0.3f, 1.0f})).Foreground());
  testing::AddDome(&scene);
  TriangleMesh mesh = synth::GroundTruthMesh(scene);
  mesh.colors.clear();
  std::vector<ColorView> views;
  for (const PinholeView& v : testing::RingRig(8, {20}, Eigen::Vector3d::Zero(), 0.8, 160, 90, 40)) {
    ColorView cv;
    cv.view = v;
    testing::ExactDepth(scene, v, &cv.image);
    views.push_back(cv);
  }
  // Vertices whose colour is clearly not their own sphere's (e.g. the other sphere's).
  auto count_wrong = [&](const TriangleMesh& m, int* coloured) {
    int wrong = 0;
    *coloured = 0;
    for (std::size_t i = 0; i < m.vertices.size(); ++i) {
      const Color3u8 c = m.colors[i];
      if (c == Color3u8(128, 128, 128)) continue;
      ++*coloured;
      const Color3u8 want = m.vertices[i].x() < 0 ? Color3u8(255, 51, 26) : Color3u8(26, 77, 255);
      // Near silhouettes a bilinear sample may blend in a little of the background.
      wrong += (c.cast<int>() - want.cast<int>()).cwiseAbs().maxCoeff() > 25;
    }
    return wrong;
  };
  ColorizeMesh(&mesh, views);
  ASSERT_TRUE(mesh.HasColors());
  int coloured = 0;
  const int wrong = count_wrong(mesh, &coloured);
  const int grey = static_cast<int>(mesh.vertices.size()) - coloured;
  // A handful at the spheres' mutual silhouettes, where the tessellated mesh
  // and the ray-cast image disagree by a pixel.
  EXPECT_LE(wrong, coloured / 1000) << wrong << " of " << coloured;
  EXPECT_GT(coloured, 5000);
  EXPECT_GT(grey, 100);  // the undersides, which no camera of the 20-degree ring sees
  // Without the visibility test the hidden sides take the other sphere's colour.
  TriangleMesh blind = mesh;
  ColoringOptions no_visibility;
  no_visibility.depth_tolerance = 10.0;
  ColorizeMesh(&blind, views, no_visibility);
  EXPECT_GT(count_wrong(blind, &coloured), 20 * std::max(wrong, 1));
  ColoringOptions bad;
  bad.min_cos = 1.5;
  EXPECT_THROW(ColorizeMesh(&mesh, views, bad), OptionError);
}

}  // namespace
}  // namespace lfrecon
