#pragma once
// A calibrated, undistorted view: the geometry every algorithm stage works
// with after ingest has removed lens distortion. Image coordinates follow
// COLMAP (upper-left pixel centre at (0.5, 0.5)); depth is planar (camera z).
#include <Eigen/Core>

#include "geometry/camera.h"
#include "geometry/rigid3.h"
#include "geometry/triangle_mesh.h"

namespace lfrecon {

struct PinholeView {
  int width = 0;
  int height = 0;
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d K_inv = Eigen::Matrix3d::Identity();
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // cam_from_world rotation
  Eigen::Vector3d t = Eigen::Vector3d::Zero();      // cam_from_world translation

  PinholeView() = default;
  // `camera` must be distortion-free (throws std::invalid_argument otherwise).
  PinholeView(const Camera& camera, const Rigid3d& cam_from_world);

  Eigen::Vector3d Center() const { return -R.transpose() * t; }
  Eigen::Vector3d ViewingDirection() const { return R.row(2).transpose(); }

  // World point -> pixel; returns its planar depth (<= 0 if behind the camera).
  double Project(const Eigen::Vector3d& world, Eigen::Vector2d* pixel) const;
  // Pixel at planar depth -> world point.
  Eigen::Vector3d Unproject(const Eigen::Vector2d& pixel, double depth) const;
  // Unit ray direction through a pixel, in world coordinates.
  Eigen::Vector3d RayDirection(const Eigen::Vector2d& pixel) const;
  bool InImage(const Eigen::Vector2d& pixel) const {
    return pixel.x() >= 0 && pixel.y() >= 0 && pixel.x() < width && pixel.y() < height;
  }
};

// Smallest and largest planar depth of the corners of `box` seen from `view`
// (negative for corners behind the camera).
void PlanarDepthRange(const PinholeView& view, const BoundingBox& box, double* zmin, double* zmax);

// Relative pose of view j with respect to view i: x_j = R_ji x_i + t_ji.
void RelativePose(const PinholeView& i, const PinholeView& j, Eigen::Matrix3d* R_ji, Eigen::Vector3d* t_ji);

// Fundamental matrix F with l_j = F * [p_i; 1] the epipolar line in j of pixel
// p_i (COLMAP pixel coordinates).
Eigen::Matrix3d FundamentalMatrix(const PinholeView& i, const PinholeView& j);

// Epipolar line (a, b, c) in view j of pixel p in view i, scaled so that
// a^2 + b^2 = 1 (then a*x + b*y + c is a signed distance in pixels).
Eigen::Vector3d EpipolarLine(const PinholeView& i, const PinholeView& j, const Eigen::Vector2d& p);

// Homography H (3x3, COLMAP pixel coordinates) that maps pixels of view i to
// view j through the plane fronto-parallel to view i at planar depth `depth`:
// [q; 1] ~ H [p; 1]. Its inverse maps j back to i through the same plane.
Eigen::Matrix3d FrontoParallelHomography(const PinholeView& i, const PinholeView& j, double depth);

// Pixel p of view i, at planar depth `depth` in i, seen in view j. Returns its
// planar depth in j (<= 0 if behind j).
double TransferPixel(const PinholeView& i, const PinholeView& j, const Eigen::Vector2d& p, double depth,
                     Eigen::Vector2d* q);

}  // namespace lfrecon
