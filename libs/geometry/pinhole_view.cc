#include "geometry/pinhole_view.h"

#include <algorithm>
#include <limits>
#include <stdexcept>

namespace lfrecon {

PinholeView::PinholeView(const Camera& camera, const Rigid3d& cam_from_world) {
  if (camera.HasDistortion())
    throw std::invalid_argument("PinholeView needs an undistorted camera, got " + CameraModelName(camera.model) +
                                " with distortion");
  width = camera.width;
  height = camera.height;
  K << camera.fx(), 0, camera.cx(), 0, camera.fy(), camera.cy(), 0, 0, 1;
  K_inv = K.inverse();
  R = cam_from_world.rotation.normalized().toRotationMatrix();
  t = cam_from_world.translation;
}

double PinholeView::Project(const Eigen::Vector3d& world, Eigen::Vector2d* pixel) const {
  const Eigen::Vector3d c = R * world + t;
  const Eigen::Vector3d h = K * c;
  *pixel = h.head<2>() / h.z();
  return c.z();
}

Eigen::Vector3d PinholeView::Unproject(const Eigen::Vector2d& pixel, double depth) const {
  const Eigen::Vector3d c = K_inv * Eigen::Vector3d(pixel.x(), pixel.y(), 1.0) * depth;
  return R.transpose() * (c - t);
}

Eigen::Vector3d PinholeView::RayDirection(const Eigen::Vector2d& pixel) const {
  return (R.transpose() * (K_inv * Eigen::Vector3d(pixel.x(), pixel.y(), 1.0))).normalized();
}

void PlanarDepthRange(const PinholeView& view, const BoundingBox& box, double* zmin, double* zmax) {
  *zmin = std::numeric_limits<double>::infinity();
  *zmax = -std::numeric_limits<double>::infinity();
  for (int c = 0; c < 8; ++c) {
    const Eigen::Vector3d corner((c & 1) ? box.max.x() : box.min.x(), (c & 2) ? box.max.y() : box.min.y(),
                                 (c & 4) ? box.max.z() : box.min.z());
    const double z = (view.R * corner + view.t).z();
    *zmin = std::min(*zmin, z);
    *zmax = std::max(*zmax, z);
  }
}

void RelativePose(const PinholeView& i, const PinholeView& j, Eigen::Matrix3d* R_ji, Eigen::Vector3d* t_ji) {
  *R_ji = j.R * i.R.transpose();
  *t_ji = j.t - *R_ji * i.t;
}

Eigen::Matrix3d FundamentalMatrix(const PinholeView& i, const PinholeView& j) {
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  RelativePose(i, j, &R, &t);
  Eigen::Matrix3d tx;
  tx << 0, -t.z(), t.y(), t.z(), 0, -t.x(), -t.y(), t.x(), 0;
  return j.K_inv.transpose() * tx * R * i.K_inv;
}

Eigen::Vector3d EpipolarLine(const PinholeView& i, const PinholeView& j, const Eigen::Vector2d& p) {
  Eigen::Vector3d l = FundamentalMatrix(i, j) * Eigen::Vector3d(p.x(), p.y(), 1.0);
  const double n = l.head<2>().norm();
  return n > 0 ? Eigen::Vector3d(l / n) : l;
}

Eigen::Matrix3d FrontoParallelHomography(const PinholeView& i, const PinholeView& j, double depth) {
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  RelativePose(i, j, &R, &t);
  // Points on the plane z_i = depth satisfy n^T x_i = depth with n = e_z, so
  // x_j = R x_i + t = (R + t n^T / depth) x_i.
  const Eigen::Matrix3d H = j.K * (R + t * Eigen::RowVector3d(0, 0, 1.0 / depth)) * i.K_inv;
  return H;
}

double TransferPixel(const PinholeView& i, const PinholeView& j, const Eigen::Vector2d& p, double depth,
                     Eigen::Vector2d* q) {
  return j.Project(i.Unproject(p, depth), q);
}

}  // namespace lfrecon
