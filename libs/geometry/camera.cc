#include "geometry/camera.h"

#include <Eigen/LU>
#include <cmath>
#include <limits>
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
    case CameraModelId::kOpenCVFisheye: return "OPENCV_FISHEYE";
    case CameraModelId::kFov: return "FOV";
    case CameraModelId::kSimpleRadialFisheye: return "SIMPLE_RADIAL_FISHEYE";
    case CameraModelId::kRadialFisheye: return "RADIAL_FISHEYE";
    case CameraModelId::kThinPrismFisheye: return "THIN_PRISM_FISHEYE";
  }
  return "UNKNOWN";
}

CameraModelId CameraModelFromName(const std::string& name) {
  for (int id = 0; id <= 10; ++id) {
    if (CameraModelName(static_cast<CameraModelId>(id)) == name) return static_cast<CameraModelId>(id);
  }
  throw std::invalid_argument("unsupported camera model '" + name +
                              "' (supported: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, "
                              "OPENCV_FISHEYE, FULL_OPENCV, FOV, SIMPLE_RADIAL_FISHEYE, RADIAL_FISHEYE, "
                              "THIN_PRISM_FISHEYE)");
}

// COLMAP's ids 0-10; 11 (RAD_TAN_THIN_PRISM_FISHEYE) and later are not supported.
bool IsSupportedCameraModelId(int id) { return id >= 0 && id <= 10; }

int NumCameraParams(CameraModelId id) {
  switch (id) {
    case CameraModelId::kSimplePinhole: return 3;
    case CameraModelId::kPinhole: return 4;
    case CameraModelId::kSimpleRadial: return 4;
    case CameraModelId::kRadial: return 5;
    case CameraModelId::kOpenCV: return 8;
    case CameraModelId::kFullOpenCV: return 12;
    case CameraModelId::kOpenCVFisheye: return 8;
    case CameraModelId::kFov: return 5;
    case CameraModelId::kSimpleRadialFisheye: return 4;
    case CameraModelId::kRadialFisheye: return 5;
    case CameraModelId::kThinPrismFisheye: return 12;
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
  return m == CameraModelId::kSimplePinhole || m == CameraModelId::kSimpleRadial || m == CameraModelId::kRadial ||
         m == CameraModelId::kSimpleRadialFisheye || m == CameraModelId::kRadialFisheye;
}

// The equidistant fisheye warp theta = atan(r) of COLMAP's fisheye models,
// with theta_d = theta (1 + k1 theta^2 + k2 theta^4 + k3 theta^6 + k4 theta^8).
Eigen::Vector2d FisheyeWarp(const Eigen::Vector2d& n, double k1, double k2, double k3, double k4) {
  const double r = n.norm();
  if (!(r > std::numeric_limits<double>::epsilon())) return n;
  const double theta = std::atan(r), t2 = theta * theta, t4 = t2 * t2;
  const double thetad = theta * (1.0 + k1 * t2 + k2 * t4 + k3 * t4 * t2 + k4 * t4 * t4);
  return n * (thetad / r);
}
}  // namespace

double Camera::fx() const { return params[0]; }
double Camera::fy() const { return SingleFocal(model) ? params[0] : params[1]; }
double Camera::cx() const { return SingleFocal(model) ? params[1] : params[2]; }
double Camera::cy() const { return SingleFocal(model) ? params[2] : params[3]; }

bool Camera::HasDistortion() const {
  // The fisheye models warp by theta = atan(r) even with zero coefficients.
  if (model == CameraModelId::kOpenCVFisheye || model == CameraModelId::kSimpleRadialFisheye ||
      model == CameraModelId::kRadialFisheye || model == CameraModelId::kThinPrismFisheye)
    return true;
  const int first = SingleFocal(model) ? 3 : 4;
  for (size_t k = first; k < params.size(); ++k)
    if (params[k] != 0.0) return true;
  return false;
}

Camera Camera::Scaled(int new_width, int new_height) const {
  if (new_width == width && new_height == height) return *this;
  const double sx = static_cast<double>(new_width) / width, sy = static_cast<double>(new_height) / height;
  Camera out = *this;
  out.width = new_width;
  out.height = new_height;
  if (!SingleFocal(model)) {
    out.params[0] *= sx;
    out.params[1] *= sy;
    out.params[2] *= sx;
    out.params[3] *= sy;
    return out;
  }
  if (sx == sy) {
    out.params[0] *= sx;
    out.params[1] *= sx;
    out.params[2] *= sy;
    return out;
  }
  // Two focal lengths needed: the equivalent two-focal model.
  const std::vector<double>& p = params;
  const double fx = p[0] * sx, fy = p[0] * sy, cx = p[1] * sx, cy = p[2] * sy;
  switch (model) {
    case CameraModelId::kSimplePinhole:
      out.model = CameraModelId::kPinhole;
      out.params = {fx, fy, cx, cy};
      break;
    case CameraModelId::kSimpleRadial:
      out.model = CameraModelId::kOpenCV;
      out.params = {fx, fy, cx, cy, p[3], 0, 0, 0};
      break;
    case CameraModelId::kRadial:
      out.model = CameraModelId::kOpenCV;
      out.params = {fx, fy, cx, cy, p[3], p[4], 0, 0};
      break;
    case CameraModelId::kSimpleRadialFisheye:
      out.model = CameraModelId::kOpenCVFisheye;
      out.params = {fx, fy, cx, cy, p[3], 0, 0, 0};
      break;
    case CameraModelId::kRadialFisheye:
      out.model = CameraModelId::kOpenCVFisheye;
      out.params = {fx, fy, cx, cy, p[3], p[4], 0, 0};
      break;
    default: break;
  }
  return out;
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
    // The fisheye models and FOV as COLMAP writes them (src/colmap/camera/models.h).
    case CameraModelId::kOpenCVFisheye: return FisheyeWarp(n, params[4], params[5], params[6], params[7]);
    case CameraModelId::kSimpleRadialFisheye: return FisheyeWarp(n, params[3], 0, 0, 0);
    case CameraModelId::kRadialFisheye: return FisheyeWarp(n, params[3], params[4], 0, 0);
    case CameraModelId::kThinPrismFisheye: {
      const Eigen::Vector2d w = FisheyeWarp(n, 0, 0, 0, 0);  // theta * n / r, then OpenCV-like terms
      const double k1 = params[4], k2 = params[5], p1 = params[6], p2 = params[7];
      const double k3 = params[8], k4 = params[9], sx1 = params[10], sy1 = params[11];
      const double a = w.x(), b = w.y(), a2 = a * a, b2 = b * b, ab = a * b, q2 = a2 + b2, q4 = q2 * q2;
      const double radial = k1 * q2 + k2 * q4 + k3 * q4 * q2 + k4 * q4 * q4;
      return {a + a * radial + 2 * p1 * ab + p2 * (q2 + 2 * a2) + sx1 * q2,
              b + b * radial + 2 * p2 * ab + p1 * (q2 + 2 * b2) + sy1 * q2};
    }
    case CameraModelId::kFov: {
      const double omega = params[4], omega2 = omega * omega;
      constexpr double kEpsilon = 1e-4;
      double factor;
      if (omega2 < kEpsilon) {
        factor = (omega2 * r2) / 3.0 - omega2 / 12.0 + 1.0;
      } else if (r2 < kEpsilon) {
        const double t = std::tan(omega / 2.0);
        factor = (-2.0 * t * (4.0 * r2 * t * t - 3.0)) / (3.0 * omega);
      } else {
        const double r = std::sqrt(r2);
        factor = std::atan(r * 2.0 * std::tan(omega / 2.0)) / (r * omega);
      }
      return n * factor;
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
