#pragma once
// A rigid transform. Poses are stored as cam_from_world (world -> camera,
// COLMAP's convention): x_cam = R * x_world + t.
#include <Eigen/Core>
#include <Eigen/Geometry>

namespace lfrecon {

struct Rigid3d {
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Rigid3d() = default;
  Rigid3d(const Eigen::Quaterniond& q, const Eigen::Vector3d& t) : rotation(q), translation(t) {}

  Eigen::Vector3d operator*(const Eigen::Vector3d& x) const { return rotation * x + translation; }
  Rigid3d Inverse() const;
  Eigen::Matrix<double, 3, 4> ToMatrix() const;
  static Rigid3d FromMatrix(const Eigen::Matrix<double, 3, 4>& m);
  bool IsFinite() const;
};

Rigid3d operator*(const Rigid3d& a, const Rigid3d& b);

// Camera centre in world coordinates of a cam_from_world pose.
Eigen::Vector3d CameraCenter(const Rigid3d& cam_from_world);
// Unit viewing direction (camera +z axis) in world coordinates.
Eigen::Vector3d ViewingDirection(const Rigid3d& cam_from_world);
// Angle in degrees between two directions (of any length). The atan2 form
// stays accurate for the tiny angles between neighbouring frames, where
// acos(dot) loses precision.
double AngleBetweenDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b);
// Angle in degrees between the viewing directions of two views.
double ViewAngleDeg(const Rigid3d& a_from_world, const Rigid3d& b_from_world);
// cam_from_world pose of a camera at `eye` looking at `target` with world `up`
// (OpenCV axes: image y points away from `up`).
Rigid3d LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, const Eigen::Vector3d& up);

}  // namespace lfrecon
