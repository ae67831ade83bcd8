#pragma once
// Camera models as COLMAP names and parameterises them. Image coordinates
// follow COLMAP: the centre of the upper-left pixel is (0.5, 0.5), so a
// centred principal point is (W/2, H/2). "Normalised" coordinates are the
// undistorted x/z, y/z of a point in the camera frame (OpenCV axes: x right,
// y down, z forward).
#include <Eigen/Core>
#include <string>
#include <vector>

namespace lfrecon {

enum class CameraModelId : int {
  kSimplePinhole = 0,  // f, cx, cy
  kPinhole = 1,        // fx, fy, cx, cy
  kSimpleRadial = 2,   // f, cx, cy, k
  kRadial = 3,         // f, cx, cy, k1, k2
  kOpenCV = 4,         // fx, fy, cx, cy, k1, k2, p1, p2
  kOpenCVFisheye = 5,  // fx, fy, cx, cy, k1, k2, k3, k4 (equidistant: theta_d = theta (1 + k1 theta^2 + ...))
  kFullOpenCV = 6,     // fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, k5, k6
  kFov = 7,            // fx, fy, cx, cy, omega
  kSimpleRadialFisheye = 8,  // f, cx, cy, k
  kRadialFisheye = 9,        // f, cx, cy, k1, k2
  kThinPrismFisheye = 10,    // fx, fy, cx, cy, k1, k2, p1, p2, k3, k4, sx1, sy1
};
// Every model above is removed on ingest (Undistorter) to PINHOLE with the same
// focal lengths and principal point, as COLMAP's image_undistorter does.

// COLMAP's name ("PINHOLE", ...) and back. CameraModelFromName throws
// std::invalid_argument for an unknown or unsupported name.
std::string CameraModelName(CameraModelId id);
CameraModelId CameraModelFromName(const std::string& name);
// COLMAP's numeric model id (as stored in cameras.bin) and back.
bool IsSupportedCameraModelId(int id);
int NumCameraParams(CameraModelId id);

struct Camera {
  CameraModelId model = CameraModelId::kPinhole;
  int width = 0;
  int height = 0;
  std::vector<double> params;

  static Camera Pinhole(int width, int height, double fx, double fy, double cx, double cy);
  // A centred pinhole camera with the given horizontal field of view.
  static Camera PinholeFromHfov(int width, int height, double hfov_deg);

  double fx() const;
  double fy() const;
  double cx() const;
  double cy() const;
  bool HasDistortion() const;
  // The camera of the same image resized to new_width x new_height: focal
  // lengths and principal point times new_width / width (x) and new_height /
  // height (y) — with the upper-left pixel's centre at (0.5, 0.5) the image
  // extent [0, W] maps onto [0, W'], so no half-pixel shift. Distortion
  // (normalised coordinates) is unchanged; a single-focal model scaled by
  // unequal factors becomes its two-focal form (PINHOLE, OPENCV, OPENCV_FISHEYE).
  Camera Scaled(int new_width, int new_height) const;
  // Empty string when valid, else what is wrong (parameter count, sizes, non-finite values).
  std::string Validate() const;

  // Normalised (undistorted) coordinates -> image pixel (applies distortion).
  Eigen::Vector2d NormalizedToImage(const Eigen::Vector2d& normalized) const;
  // Image pixel -> normalised (undistorted) coordinates (inverts distortion).
  Eigen::Vector2d ImageToNormalized(const Eigen::Vector2d& pixel) const;
  // Camera-frame point -> pixel; returns false if behind the camera.
  bool Project(const Eigen::Vector3d& point_cam, Eigen::Vector2d* pixel) const;
  // Pixel -> camera-frame point at planar depth z.
  Eigen::Vector3d Unproject(const Eigen::Vector2d& pixel, double depth) const;

  // The distortion model on normalised coordinates, and its iterative inverse.
  Eigen::Vector2d Distort(const Eigen::Vector2d& undistorted) const;
  Eigen::Vector2d Undistort(const Eigen::Vector2d& distorted) const;

  // Same model, size and parameters (exactly).
  bool operator==(const Camera& other) const {
    return model == other.model && width == other.width && height == other.height && params == other.params;
  }
  bool operator!=(const Camera& other) const { return !(*this == other); }
};

}  // namespace lfrecon
