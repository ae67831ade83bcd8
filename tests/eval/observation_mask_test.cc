// Observation masks (BRIEF §4): a ground-truth point counts when some
// ground-truth depth map sees it unoccluded. Unit cases on a flat depth map,
// then a cube standing on a plane with cameras circling above it: its bottom
// face (1/6 of its area) is hidden from every view, so the observed share is
// 5/6, and a reconstruction of the five visible faces has observed recall 1
// while its unmasked recall is 5/6 plus the band of the bottom face within τ
// of the side faces.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "eval/mesh_metrics.h"
#include "geometry/camera.h"
#include "synth/camera_path.h"
#include "synth/gt_mesh.h"
#include "synth/renderer.h"
#include "synth/scene.h"
#include "util/error.h"

namespace lfrecon {
namespace {

// A camera at the origin looking down +z (identity pose), 100 x 80 px.
PinholeView FrontView() { return PinholeView(Camera::Pinhole(100, 80, 100, 100, 50, 40), Rigid3d()); }

TEST(ObservationMask, FlatDepthMap) {
  const PinholeView view = FrontView();
  cv::Mat depth(80, 100, CV_32F, cv::Scalar(1.0f));  // a wall at z = 1 m
  depth(cv::Rect(80, 0, 20, 80)).setTo(0.0f);         // no surface in the right fifth of the image
  const std::vector<Eigen::Vector3d> points = {
      {0, 0, 1.0},          // 0: on the wall
      {0, 0, 0.5},          // 1: in front of it
      {0.01, 0, 1.0015},    // 2: behind it, within the tolerance (max(2 mm, 0.25 % of 1 m) = 2.5 mm)
      {0.01, 0, 1.01},      // 3: behind it by 1 cm: hidden
      {0.5, 0, 1.5},        // 4: behind where the map has no surface (pixel x = 83.3)
      {2.0, 0, 1.0},        // 5: outside the image (pixel x = 250)
      {0, 0, -1.0},         // 6: behind the camera
  };
  ObservationMask mask(&points, ObservationOptions{});
  mask.Add(view, depth);
  EXPECT_EQ(mask.observed(), (std::vector<std::uint8_t>{1, 1, 1, 0, 1, 0, 0}));
  EXPECT_EQ(mask.NumObserved(), 4u);
  EXPECT_EQ(mask.NumViews(), 1);

  // A second map that shows the wall further away reveals point 3; what was seen stays seen.
  cv::Mat far(80, 100, CV_32F, cv::Scalar(1.02f));
  mask.Add(view, far);
  EXPECT_EQ(mask.observed()[3], 1);
  EXPECT_EQ(mask.NumObserved(), 5u);

  // A relative tolerance of 1 % at 1.01 m (10.1 mm) also accepts point 3 from the first map.
  ObservationOptions loose;
  loose.relative_tolerance = 0.01;
  EXPECT_EQ(ObservedMask(points, GroundTruthViews{{view}, [&](int) { return depth; }}, loose)[3], 1);

  EXPECT_THROW(mask.Add(view, cv::Mat(40, 50, CV_32F, cv::Scalar(1.0f))), std::invalid_argument);
  ObservationOptions bad;
  bad.support_px = 0;
  EXPECT_THROW(ObservationMask(&points, bad), OptionError);
}

TEST(ObservationMask, SupportReachesPastAnEdge) {
  // A step: left half of the image at 1 m, right half at 2 m (the edge between columns 49 and 50).
  const PinholeView view = FrontView();
  cv::Mat depth(80, 100, CV_32F, cv::Scalar(1.0f));
  depth(cv::Rect(50, 0, 50, 80)).setTo(2.0f);
  // Points at 2 m (the far half's surface, extended) projecting at x = 49.6 and 49.4,
  // both hidden behind the near half (pixel centres at c + 0.5). The 2 x 2 support
  // of the first is columns 49, 50 and holds the far half; that of the second,
  // columns 48, 49, does not. 3 x 3 around the nearest pixel (49) holds it for both;
  // the nearest pixel alone for neither.
  const std::vector<Eigen::Vector3d> points = {{(49.6 - 50) / 100 * 2.0, 0, 2.0}, {(49.4 - 50) / 100 * 2.0, 0, 2.0}};
  auto mask_with = [&](int support_px) {
    ObservationOptions o;
    o.support_px = support_px;
    ObservationMask m(&points, o);
    m.Add(view, depth);
    return m.observed();
  };
  EXPECT_EQ(mask_with(2), (std::vector<std::uint8_t>{1, 0}));
  EXPECT_EQ(mask_with(3), (std::vector<std::uint8_t>{1, 1}));
  EXPECT_EQ(mask_with(1), (std::vector<std::uint8_t>{0, 0}));
}

// A 0.4 m cube standing on the plane z = 0, 24 cameras on a circle of radius
// 0.7 m at height 1.4 m looking at its centre (elevation ~60°), 640 x 480 at
// 60° horizontal field of view (~2.5 mm per pixel at the cube).
class HiddenFace : public ::testing::Test {
 protected:
  static constexpr double kSide = 0.4;

  static void SetUpTestSuite() {
    synth::Scene scene("cube_on_plane");
    scene.Add(synth::Primitive::Box({0, 0, kSide / 2}, Eigen::Vector3d::Constant(kSide / 2),
                                    synth::Material::Flat({0.8f, 0.3f, 0.3f}))
                  .Foreground());
    scene.Add(synth::Primitive::Plane({0, 0, 0}, {0, 0, 1}, synth::Material::Flat({0.5f, 0.5f, 0.5f})));
    cube_ = new TriangleMesh(synth::TessellatePrimitive(scene.primitive(0)));

    synth::CameraPathOptions path;
    path.num_frames = 24;
    path.target = {0, 0, kSide / 2};
    path.radius = 0.7;
    path.height = 1.4;
    const Camera camera = Camera::PinholeFromHfov(640, 480, 60);
    synth::RenderOptions render;
    render.supersampling = 1;
    render.noise_sigma = 0;
    views_ = new GroundTruthViews;
    depths_ = new std::vector<cv::Mat>;
    for (const Rigid3d& pose : synth::MakeCameraPath(path)) {
      views_->views.emplace_back(camera, pose);
      depths_->push_back(synth::DepthToFloat(synth::Render(scene, views_->views.back(), render, 0).depth));
    }
    views_->load = [](int k) { return (*depths_)[static_cast<std::size_t>(k)]; };
  }
  static void TearDownTestSuite() {
    delete cube_;
    delete views_;
    delete depths_;
  }

  static bool OnBottom(const Eigen::Vector3d& p) { return std::abs(p.z()) < 1e-6; }
  // The cube's five visible faces: its tessellation without the bottom face's triangles.
  static TriangleMesh FiveFaces() {
    TriangleMesh m = *cube_;
    m.triangles.clear();
    for (const Eigen::Vector3i& t : cube_->triangles) {
      const double z = (cube_->vertices[t[0]].z() + cube_->vertices[t[1]].z() + cube_->vertices[t[2]].z()) / 3.0;
      if (std::abs(z) > 1e-6) m.triangles.push_back(t);
    }
    return m;
  }

  static TriangleMesh* cube_;
  static GroundTruthViews* views_;
  static std::vector<cv::Mat>* depths_;
};
TriangleMesh* HiddenFace::cube_ = nullptr;
GroundTruthViews* HiddenFace::views_ = nullptr;
std::vector<cv::Mat>* HiddenFace::depths_ = nullptr;

TEST_F(HiddenFace, BottomFaceIsUnobserved) {
  const std::vector<Eigen::Vector3d> samples = SampleSurface(*cube_, 0.004, 7);  // ~60k
  ASSERT_GT(samples.size(), 50000u);
  const std::vector<std::uint8_t> seen = ObservedMask(samples, *views_, ObservationOptions{});
  std::size_t bottom = 0, bottom_seen = 0, sides = 0, sides_seen = 0;
  double widest_leak = 0;  // farthest observed bottom sample from the bottom face's boundary
  for (std::size_t i = 0; i < samples.size(); ++i) {
    if (OnBottom(samples[i])) {
      ++bottom;
      if (seen[i]) {
        ++bottom_seen;
        const double h = kSide / 2;
        widest_leak = std::max(widest_leak, std::min(h - std::abs(samples[i].x()), h - std::abs(samples[i].y())));
      }
    } else {
      ++sides;
      sides_seen += seen[i];
    }
  }
  const double share = static_cast<double>(std::count(seen.begin(), seen.end(), 1)) / samples.size();
  // Six equal faces of 0.16 m² at one sample per 16 mm²: exactly 10000 each.
  EXPECT_EQ(bottom * 6, samples.size());
  // The top and the four sides are seen whole.
  EXPECT_EQ(sides_seen, sides);
  // The bottom is hidden except a band along its edges: hidden points whose
  // support (2 x 2 pixels, ~2.5 mm each, seen at ~60° elevation: ~4 mm on the
  // bottom face) reaches the plane beyond the edge, or that lie within the
  // tolerance (3.5 mm in depth, ~1.8 mm on the face) behind a side face.
  // (Measured: 3.9 mm; 3.4 % of the bottom's samples.)
  EXPECT_LT(widest_leak, 0.005);
  // A band of at most 5 mm along the 400 mm square's 4 sides is < 5 % of the
  // bottom, < 0.0083 of the cube's samples.
  EXPECT_GE(share, 5.0 / 6.0 - 1e-9);
  EXPECT_LT(share, 5.0 / 6.0 + 0.0083);
  RecordProperty("observed_share", std::to_string(share));
  RecordProperty("bottom_observed", std::to_string(static_cast<double>(bottom_seen) / bottom));
  std::printf("observed share %.4f (5/6 = %.4f); bottom samples observed %zu of %zu, widest band %.2f mm\n", share,
              5.0 / 6.0, bottom_seen, bottom, widest_leak * 1000);
}

TEST_F(HiddenFace, MaskedRecallOfTheVisibleFacesIsOne) {
  const TriangleMesh five = FiveFaces();
  MeshMetricsOptions o;
  o.sample_spacing = 0.004;
  const MeshMetrics m = EvaluateMesh(five, *cube_, nullptr, o, views_);
  ASSERT_TRUE(m.has_observation);
  EXPECT_EQ(m.observation_views, 24);
  EXPECT_NEAR(m.ObservedShare(), 5.0 / 6.0, 0.012);
  for (const ThresholdScore& s : m.scores) {
    // Unmasked: the sides and top, plus the band of the bottom within τ of the sides.
    const double band = 1 - std::pow(1 - 2 * s.threshold / kSide, 2);
    EXPECT_NEAR(s.recall, (5 + band) / 6, 0.005) << "tau " << s.threshold;
    EXPECT_DOUBLE_EQ(s.precision, 1.0);
    EXPECT_NEAR(s.fscore, 2 * s.recall / (1 + s.recall), 1e-12);
    EXPECT_EQ(s.thin_recall_observed, -1);  // no thin ground truth
  }
  // Masked: everything observed is reconstructed, up to the band's points more than τ from the sides.
  EXPECT_GT(m.Find(0.002)->recall_observed, 0.99);
  EXPECT_GT(m.Find(0.005)->recall_observed, 0.999);
  EXPECT_DOUBLE_EQ(m.Find(0.010)->recall_observed, 1.0);
  EXPECT_DOUBLE_EQ(m.Find(0.010)->fscore_observed, 1.0);
  EXPECT_LT(m.Find(0.010)->fscore, 0.93);
  EXPECT_LT(m.median_completeness_observed, 1e-6);

  // Without views: no observed figures.
  const MeshMetrics u = EvaluateMesh(five, *cube_, nullptr, o);
  EXPECT_FALSE(u.has_observation);
  EXPECT_EQ(u.Find(0.005)->recall_observed, -1);
  EXPECT_EQ(u.Find(0.005)->recall, m.Find(0.005)->recall);
}

TEST_F(HiddenFace, ThinGroundTruthIsMaskedToo) {
  // The cube's bottom face given as "thin" ground truth: hidden, so almost none of it counts.
  TriangleMesh bottom = *cube_;
  bottom.triangles.clear();
  for (const Eigen::Vector3i& t : cube_->triangles)
    if (OnBottom(cube_->vertices[t[0]].cast<double>()) && OnBottom(cube_->vertices[t[1]].cast<double>()) &&
        OnBottom(cube_->vertices[t[2]].cast<double>()))
      bottom.triangles.push_back(t);
  MeshMetricsOptions o;
  o.sample_spacing = 0.004;
  const MeshMetrics m = EvaluateMesh(FiveFaces(), *cube_, &bottom, o, views_);
  EXPECT_GT(m.thin_samples, 9000u);
  EXPECT_LT(m.ThinObservedShare(), 0.07);
  EXPECT_LT(m.Find(0.005)->thin_recall, 0.06);
  EXPECT_GT(m.Find(0.005)->thin_recall_observed, 0.98);
}

}  // namespace
}  // namespace lfrecon
