#include "geometry/camera.h"

#include <gtest/gtest.h>

#include <opencv2/core.hpp>
#include <random>

#include "geometry/undistorter.h"

namespace lfrecon {
namespace {

std::vector<Camera> AllModels() {
  const int w = 640, h = 480;
  std::vector<Camera> cams;
  Camera c;
  c.width = w;
  c.height = h;
  c.model = CameraModelId::kSimplePinhole;
  c.params = {500, 320, 240};
  cams.push_back(c);
  c.model = CameraModelId::kPinhole;
  c.params = {500, 510, 321, 239};
  cams.push_back(c);
  c.model = CameraModelId::kSimpleRadial;
  c.params = {500, 320, 240, -0.08};
  cams.push_back(c);
  c.model = CameraModelId::kRadial;
  c.params = {500, 320, 240, -0.08, 0.02};
  cams.push_back(c);
  c.model = CameraModelId::kOpenCV;
  c.params = {500, 505, 320, 240, -0.1, 0.03, 0.001, -0.002};
  cams.push_back(c);
  c.model = CameraModelId::kFullOpenCV;
  c.params = {500, 505, 320, 240, -0.1, 0.03, 0.001, -0.002, 0.001, 0.01, 0.002, 0.0005};
  cams.push_back(c);
  // COLMAP's fisheye models and FOV (undistorted through cv::fisheye for the first three).
  c.model = CameraModelId::kOpenCVFisheye;
  c.params = {300, 305, 320, 240, 0.05, -0.01, 0.002, -0.0005};
  cams.push_back(c);
  c.model = CameraModelId::kSimpleRadialFisheye;
  c.params = {300, 320, 240, 0.04};
  cams.push_back(c);
  c.model = CameraModelId::kRadialFisheye;
  c.params = {300, 322, 238, 0.04, -0.006};
  cams.push_back(c);
  c.model = CameraModelId::kThinPrismFisheye;
  c.params = {300, 305, 320, 240, 0.03, -0.01, 0.001, -0.002, 0.001, 0.0005, 0.001, -0.001};
  cams.push_back(c);
  c.model = CameraModelId::kFov;
  c.params = {300, 305, 320, 240, 0.6};
  cams.push_back(c);
  return cams;
}

TEST(Camera, NamesRoundTrip) {
  for (const Camera& c : AllModels()) {
    EXPECT_EQ(CameraModelFromName(CameraModelName(c.model)), c.model);
    EXPECT_EQ(NumCameraParams(c.model), static_cast<int>(c.params.size()));
    EXPECT_EQ(c.Validate(), "");
  }
  EXPECT_THROW(CameraModelFromName("FISHEYE_XYZ"), std::invalid_argument);
  EXPECT_EQ(AllModels().size(), 11u);  // COLMAP's models 0-10
  EXPECT_EQ(CameraModelName(CameraModelId::kOpenCVFisheye), "OPENCV_FISHEYE");
  EXPECT_EQ(static_cast<int>(CameraModelFromName("THIN_PRISM_FISHEYE")), 10);
  EXPECT_FALSE(IsSupportedCameraModelId(11));
}

// The equidistant warp: a ray at angle theta from the axis lands at radius
// f * theta (1 + k theta^2) (COLMAP's SIMPLE_RADIAL_FISHEYE), not f * tan(theta).
TEST(Camera, FisheyeIsEquidistant) {
  Camera c;
  c.model = CameraModelId::kSimpleRadialFisheye;
  c.width = 640;
  c.height = 480;
  c.params = {300, 320, 240, 0.04};
  const double theta = 0.6;
  Eigen::Vector2d p;
  ASSERT_TRUE(c.Project(Eigen::Vector3d(std::sin(theta), 0, std::cos(theta)), &p));
  EXPECT_NEAR(p.x() - 320, 300 * theta * (1 + 0.04 * theta * theta), 1e-9);
  EXPECT_TRUE(c.HasDistortion());
  c.params[3] = 0;
  EXPECT_TRUE(c.HasDistortion());  // zero coefficients still warp
}

TEST(Camera, ProjectUnprojectRoundTripEveryModel) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ux(0.0, 640.0), uy(0.0, 480.0), ud(0.3, 20.0);
  for (const Camera& c : AllModels()) {
    double max_err = 0;
    for (int k = 0; k < 2000; ++k) {
      const Eigen::Vector2d p(ux(rng), uy(rng));
      const double d = ud(rng);
      const Eigen::Vector3d X = c.Unproject(p, d);
      EXPECT_NEAR(X.z(), d, 1e-12);
      Eigen::Vector2d q;
      ASSERT_TRUE(c.Project(X, &q));
      max_err = std::max(max_err, (q - p).norm());
    }
    EXPECT_LT(max_err, 1e-6) << CameraModelName(c.model);
  }
}

TEST(Camera, DistortionInverse) {
  for (const Camera& c : AllModels()) {
    for (double u = -0.5; u <= 0.5; u += 0.05)
      for (double v = -0.4; v <= 0.4; v += 0.05) {
        const Eigen::Vector2d n(u, v);
        EXPECT_LT((c.Undistort(c.Distort(n)) - n).norm(), 1e-10) << CameraModelName(c.model);
      }
  }
}

TEST(Camera, PixelConventionCentreIsHalfSize) {
  const Camera c = Camera::PinholeFromHfov(640, 360, 55.0);
  Eigen::Vector2d p;
  ASSERT_TRUE(c.Project(Eigen::Vector3d(0, 0, 1), &p));
  EXPECT_DOUBLE_EQ(p.x(), 320.0);
  EXPECT_DOUBLE_EQ(p.y(), 180.0);
}

TEST(Camera, ValidateRejectsBadCameras) {
  Camera c = Camera::Pinhole(640, 480, 500, 500, 320, 240);
  c.params.pop_back();
  EXPECT_NE(c.Validate(), "");
  c = Camera::Pinhole(0, 480, 500, 500, 320, 240);
  EXPECT_NE(c.Validate(), "");
  c = Camera::Pinhole(640, 480, std::nan(""), 500, 320, 240);
  EXPECT_NE(c.Validate(), "");
}

// A smooth pattern defined on normalised coordinates, rendered through the
// distorted camera, must come out of the Undistorter as the same pattern
// rendered through the pinhole camera.
TEST(Undistorter, UndistortedFrameMatchesPinholeRendering) {
  auto pattern = [](const Eigen::Vector2d& n) {
    return static_cast<float>(0.5 + 0.25 * std::sin(9.0 * n.x()) + 0.25 * std::cos(7.0 * n.y()));
  };
  for (const Camera& c : AllModels()) {
    if (!c.HasDistortion()) continue;
    cv::Mat distorted(c.height, c.width, CV_32F);
    for (int r = 0; r < c.height; ++r)
      for (int col = 0; col < c.width; ++col)
        distorted.at<float>(r, col) = pattern(c.ImageToNormalized(Eigen::Vector2d(col + 0.5, r + 0.5)));
    Undistorter und(c);
    ASSERT_FALSE(und.is_identity());
    const cv::Mat out = und.Apply(distorted);
    const Camera& pin = und.undistorted_camera();
    EXPECT_FALSE(pin.HasDistortion());
    double max_err = 0;
    // Skip a border: there the undistorted image samples outside the source.
    for (int r = 40; r < c.height - 40; ++r)
      for (int col = 40; col < c.width - 40; ++col) {
        const float expect = pattern(pin.ImageToNormalized(Eigen::Vector2d(col + 0.5, r + 0.5)));
        max_err = std::max(max_err, static_cast<double>(std::abs(out.at<float>(r, col) - expect)));
      }
    EXPECT_LT(max_err, 2e-3) << CameraModelName(c.model);
  }
}

TEST(Undistorter, RejectsWrongImageSize) {
  AllModels();
  Undistorter und(AllModels()[4]);
  EXPECT_THROW(und.Apply(cv::Mat(100, 100, CV_32F)), std::invalid_argument);
}

}  // namespace
}  // namespace lfrecon
