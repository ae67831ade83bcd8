#include "geometry/rigid3.h"

#include <algorithm>
#include <cmath>

namespace lfrecon {

Rigid3d Rigid3d::Inverse() const {
  const Eigen::Quaterniond qi = rotation.inverse();
  return Rigid3d(qi, -(qi * translation));
}

Eigen::Matrix<double, 3, 4> Rigid3d::ToMatrix() const {
  Eigen::Matrix<double, 3, 4> m;
  m.leftCols<3>() = rotation.toRotationMatrix();
  m.col(3) = translation;
  return m;
}

Rigid3d Rigid3d::FromMatrix(const Eigen::Matrix<double, 3, 4>& m) {
  Eigen::Quaterniond q(Eigen::Matrix3d(m.leftCols<3>()));
  q.normalize();
  return Rigid3d(q, m.col(3));
}

bool Rigid3d::IsFinite() const { return rotation.coeffs().allFinite() && translation.allFinite(); }

Rigid3d operator*(const Rigid3d& a, const Rigid3d& b) {
  return Rigid3d((a.rotation * b.rotation).normalized(), a.rotation * b.translation + a.translation);
}

Eigen::Vector3d CameraCenter(const Rigid3d& cam_from_world) {
  return -(cam_from_world.rotation.inverse() * cam_from_world.translation);
}

Eigen::Vector3d ViewingDirection(const Rigid3d& cam_from_world) {
  return cam_from_world.rotation.inverse() * Eigen::Vector3d::UnitZ();
}

double AngleBetweenDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b)) * 180.0 / M_PI;
}

double ViewAngleDeg(const Rigid3d& a, const Rigid3d& b) {
  return AngleBetweenDeg(ViewingDirection(a), ViewingDirection(b));
}

Rigid3d LookAt(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, const Eigen::Vector3d& up) {
  const Eigen::Vector3d z = (target - eye).normalized();
  Eigen::Vector3d x = z.cross(up);
  if (x.norm() < 1e-12) x = z.unitOrthogonal();
  x.normalize();
  const Eigen::Vector3d y = z.cross(x);  // points "down" relative to up
  Eigen::Matrix3d world_from_cam;
  world_from_cam.col(0) = x;
  world_from_cam.col(1) = y;
  world_from_cam.col(2) = z;
  const Eigen::Matrix3d R = world_from_cam.transpose();
  Eigen::Quaterniond q(R);
  q.normalize();
  return Rigid3d(q, -(R * eye));
}

}  // namespace lfrecon
