#include "geometry/camera.h"

#include <Eigen/LU>
#include <cmath>
#include <stdexcept>

namespace lfrecon {

std::string CameraModelName(CameraModelId id) {
  switch (id) {
    case CameraModelId::kSimplePinhole: return "SIMPLE_PINHOLE";
    case CameraModelId::kPinhole: return "PINHOLE";
    case CameraModelId::kSimpleRadial: return "SIMPLE_RADIAL";
    case CameraModelId::kRadial: return "RADIAL";
    case CameraModelId::kOpenCV: return "OPENCV";
    case CameraModelId::kFullOpenCV: return "FULL_OPENCV";
  }
  return "UNKNOWN";
}

CameraModelId CameraModelFromName(const std::string& name) {
  for (CameraModelId id : {CameraModelId::kSimplePinhole, CameraModelId::kPinhole, CameraModelId::kSimpleRadial,
                           CameraModelId::kRadial, CameraModelId::kOpenCV, CameraModelId::kFullOpenCV}) {
    if (CameraModelName(id) == name) return id;
  }
  throw std::invalid_argument("unsupported camera model '" + name +
                              "' (supported: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV)");
}

bool IsSupportedCameraModelId(int id) { return (id >= 0 && id <= 4) || id == 6; }

int NumCameraParams(CameraModelId id) {
  switch (id) {
    case CameraModelId::kSimplePinhole: return 3;
    case CameraModelId::kPinhole: return 4;
    case CameraModelId::kSimpleRadial: return 4;
    case CameraModelId::kRadial: return 5;
    case CameraModelId::kOpenCV: return 8;
    case CameraModelId::kFullOpenCV: return 12;
  }
  return 0;
}

Camera Camera::Pinhole(int width, int height, double fx, double fy, double cx, double cy) {
  Camera c;
  c.model = CameraModelId::kPinhole;
  c.width = width;
  c.height = height;
  c.params = {fx, fy, cx, cy};
  return c;
}

Camera Camera::PinholeFromHfov(int width, int height, double hfov_deg) {
  const double f = 0.5 * width / std::tan(0.5 * hfov_deg * M_PI / 180.0);
  return Pinhole(width, height, f, f, 0.5 * width, 0.5 * height);
}

namespace {
bool SingleFocal(CameraModelId m) {
  return m == CameraModelId::kSimplePinhole || m == CameraModelId::kSimpleRadial || m == CameraModelId::kRadial;
}
}  // namespace

double Camera::fx() const { return params[0]; }
double Camera::fy() const { return SingleFocal(model) ? params[0] : params[1]; }
double Camera::cx() const { return SingleFocal(model) ? params[1] : params[2]; }
double Camera::cy() const { return SingleFocal(model) ? params[2] : params[3]; }

bool Camera::HasDistortion() const {
  const int first = SingleFocal(model) ? 3 : 4;
  for (size_t k = first; k < params.size(); ++k)
    if (params[k] != 0.0) return true;
  return false;
}

std::string Camera::Validate() const {
  if (static_cast<int>(params.size()) != NumCameraParams(model))
    return CameraModelName(model) + " needs " + std::to_string(NumCameraParams(model)) + " parameters, got " +
           std::to_string(params.size());
  if (width <= 0 || height <= 0) return "image size must be positive, got " + std::to_string(width) + "x" +
                                        std::to_string(height);
  for (double p : params)
    if (!std::isfinite(p)) return "non-finite camera parameter";
  if (fx() <= 0 || fy() <= 0) return "focal length must be positive";
  return "";
}

Eigen::Vector2d Camera::Distort(const Eigen::Vector2d& n) const {
  const double u = n.x(), v = n.y();
  const double u2 = u * u, v2 = v * v, uv = u * v, r2 = u2 + v2;
  switch (model) {
    case CameraModelId::kSimplePinhole:
    case CameraModelId::kPinhole:
      return n;
    case CameraModelId::kSimpleRadial: {
      const double radial = 1.0 + params[3] * r2;
      return n * radial;
    }
    case CameraModelId::kRadial: {
      const double radial = 1.0 + params[3] * r2 + params[4] * r2 * r2;
      return n * radial;
    }
    case CameraModelId::kOpenCV: {
      const double k1 = params[4], k2 = params[5], p1 = params[6], p2 = params[7];
      const double radial = 1.0 + k1 * r2 + k2 * r2 * r2;
      return {u * radial + 2 * p1 * uv + p2 * (r2 + 2 * u2), v * radial + 2 * p2 * uv + p1 * (r2 + 2 * v2)};
    }
    case CameraModelId::kFullOpenCV: {
      const double k1 = params[4], k2 = params[5], p1 = params[6], p2 = params[7];
      const double k3 = params[8], k4 = params[9], k5 = params[10], k6 = params[11];
      const double r4 = r2 * r2, r6 = r4 * r2;
      const double radial = (1.0 + k1 * r2 + k2 * r4 + k3 * r6) / (1.0 + k4 * r2 + k5 * r4 + k6 * r6);
      return {u * radial + 2 * p1 * uv + p2 * (r2 + 2 * u2), v * radial + 2 * p2 * uv + p1 * (r2 + 2 * v2)};
    }
  }
  return n;
}

Eigen::Vector2d Camera::Undistort(const Eigen::Vector2d& d) const {
  if (model == CameraModelId::kPinhole || model == CameraModelId::kSimplePinhole) return d;
  // Newton iterations with a numerical Jacobian, as COLMAP does: the models
  // are smooth and near identity over the image, so this converges in a few steps.
  Eigen::Vector2d x = d;
  constexpr double kEps = 1e-9;
  for (int it = 0; it < 100; ++it) {
    const Eigen::Vector2d fx = Distort(x) - d;
    if (fx.squaredNorm() < 1e-30) break;
    Eigen::Matrix2d J;
    J.col(0) = (Distort(x + Eigen::Vector2d(kEps, 0)) - Distort(x - Eigen::Vector2d(kEps, 0))) / (2 * kEps);
    J.col(1) = (Distort(x + Eigen::Vector2d(0, kEps)) - Distort(x - Eigen::Vector2d(0, kEps))) / (2 * kEps);
    const Eigen::Vector2d step = J.inverse() * fx;
    x -= step;
    if (step.squaredNorm() < 1e-28) break;
  }
  return x;
}

Eigen::Vector2d Camera::NormalizedToImage(const Eigen::Vector2d& normalized) const {
  const Eigen::Vector2d d = Distort(normalized);
  return {fx() * d.x() + cx(), fy() * d.y() + cy()};
}

Eigen::Vector2d Camera::ImageToNormalized(const Eigen::Vector2d& pixel) const {
  const Eigen::Vector2d d((pixel.x() - cx()) / fx(), (pixel.y() - cy()) / fy());
  return Undistort(d);
}

bool Camera::Project(const Eigen::Vector3d& p, Eigen::Vector2d* pixel) const {
  if (p.z() <= 0) return false;
  *pixel = NormalizedToImage(p.head<2>() / p.z());
  return true;
}

Eigen::Vector3d Camera::Unproject(const Eigen::Vector2d& pixel, double depth) const {
  const Eigen::Vector2d n = ImageToNormalized(pixel);
  return {n.x() * depth, n.y() * depth, depth};
}

}  // namespace lfrecon
