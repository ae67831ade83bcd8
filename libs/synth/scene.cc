#include "synth/scene.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace lfrecon::synth {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// Both roots of a t^2 + 2 b t + c = 0 in ascending order, computed without
// cancellation; false if there is no real root.
inline bool SolveQuadratic(double a, double b, double c, double* t0, double* t1) {
  const double disc = b * b - a * c;
  if (disc < 0 || a <= 0) return false;
  const double q = -(b + std::copysign(std::sqrt(disc), b));
  if (q == 0) return false;
  double r0 = q / a, r1 = c / q;
  if (r0 > r1) std::swap(r0, r1);
  *t0 = r0;
  *t1 = r1;
  return true;
}

// Orthonormal frame whose third column is `z`.
Eigen::Matrix3d FrameFromAxis(const Eigen::Vector3d& z) {
  const Eigen::Vector3d w = z.normalized();
  const Eigen::Vector3d u = w.unitOrthogonal();
  Eigen::Matrix3d m;
  m.col(0) = u;
  m.col(1) = w.cross(u);
  m.col(2) = w;
  return m;
}

}  // namespace

std::string PrimitiveTypeName(PrimitiveType type) {
  switch (type) {
    case PrimitiveType::kSphere:
      return "sphere";
    case PrimitiveType::kBox:
      return "box";
    case PrimitiveType::kCylinder:
      return "cylinder";
    case PrimitiveType::kPlane:
      return "plane";
  }
  return "unknown";
}

Primitive Primitive::Sphere(const Eigen::Vector3d& center, double radius, const Material& material) {
  if (!(radius > 0)) throw std::invalid_argument("sphere radius must be positive");
  Primitive p;
  p.type = PrimitiveType::kSphere;
  p.name = "sphere";
  p.center = center;
  p.radius = radius;
  p.material = material;
  return p;
}

Primitive Primitive::Box(const Eigen::Vector3d& center, const Eigen::Vector3d& half_size,
                         const Material& material, const Eigen::Matrix3d& axes) {
  if (!(half_size.array() > 0).all()) throw std::invalid_argument("box half sizes must be positive");
  Primitive p;
  p.type = PrimitiveType::kBox;
  p.name = "box";
  p.center = center;
  // Re-orthonormalise so a slightly inexact rotation does not skew the box.
  p.axes = Eigen::Quaterniond(axes).normalized().toRotationMatrix();
  p.half_size = half_size;
  p.material = material;
  return p;
}

Primitive Primitive::Cylinder(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, double radius,
                              const Material& material, bool cap0, bool cap1) {
  const double length = (p1 - p0).norm();
  if (!(radius > 0) || !(length > 0))
    throw std::invalid_argument("cylinder radius and length must be positive");
  Primitive p;
  p.type = PrimitiveType::kCylinder;
  p.name = "cylinder";
  p.center = p0;
  p.axes = FrameFromAxis(p1 - p0);
  p.length = length;
  p.radius = radius;
  p.cap0 = cap0;
  p.cap1 = cap1;
  p.material = material;
  return p;
}

Primitive Primitive::Plane(const Eigen::Vector3d& point, const Eigen::Vector3d& normal,
                           const Material& material) {
  if (!(normal.norm() > 0)) throw std::invalid_argument("plane normal must be non-zero");
  Primitive p;
  p.type = PrimitiveType::kPlane;
  p.name = "plane";
  p.center = point;
  p.axes = FrameFromAxis(normal);
  p.half_size = Eigen::Vector3d(kInf, kInf, 0);
  p.material = material;
  return p;
}

Primitive Primitive::Rect(const Eigen::Vector3d& center, const Eigen::Vector3d& u, const Eigen::Vector3d& v,
                          double half_u, double half_v, const Material& material) {
  const Eigen::Vector3d uu = u.normalized();
  const Eigen::Vector3d vv = (v - v.dot(uu) * uu).normalized();
  if (!uu.allFinite() || !vv.allFinite() || !(half_u > 0) || !(half_v > 0))
    throw std::invalid_argument("rectangle needs independent axes and positive half extents");
  Primitive p;
  p.type = PrimitiveType::kPlane;
  p.name = "rect";
  p.center = center;
  p.axes.col(0) = uu;
  p.axes.col(1) = vv;
  p.axes.col(2) = uu.cross(vv);
  p.half_size = Eigen::Vector3d(half_u, half_v, 0);
  p.material = material;
  return p;
}

bool Primitive::IsBounded() const {
  return type != PrimitiveType::kPlane || (std::isfinite(half_size.x()) && std::isfinite(half_size.y()));
}

void Primitive::BoundingSphere(Eigen::Vector3d* c, double* r) const {
  switch (type) {
    case PrimitiveType::kSphere:
      *c = center;
      *r = radius;
      return;
    case PrimitiveType::kBox:
      *c = center;
      *r = half_size.norm();
      return;
    case PrimitiveType::kCylinder:
      *c = center + 0.5 * length * axes.col(2);
      *r = std::hypot(0.5 * length, radius);
      return;
    case PrimitiveType::kPlane:
      *c = center;
      *r = IsBounded() ? std::hypot(half_size.x(), half_size.y()) : kInf;
      return;
  }
}

double Primitive::ThinSize() const {
  switch (type) {
    case PrimitiveType::kSphere:
    case PrimitiveType::kCylinder:
      return radius;
    case PrimitiveType::kBox: {
      Eigen::Vector3d h = half_size;
      std::sort(h.data(), h.data() + 3);
      return h[1];
    }
    case PrimitiveType::kPlane:
      return kInf;
  }
  return kInf;
}

double Primitive::SurfaceDistance(const Eigen::Vector3d& p) const {
  switch (type) {
    case PrimitiveType::kSphere:
      return std::abs((p - center).norm() - radius);
    case PrimitiveType::kBox: {
      const Eigen::Vector3d q = (axes.transpose() * (p - center)).cwiseAbs() - half_size;
      const double outside = q.cwiseMax(0.0).norm();
      const double inside = std::min(q.maxCoeff(), 0.0);
      return std::abs(outside + inside);
    }
    case PrimitiveType::kCylinder: {
      const Eigen::Vector3d w = p - center;
      const double s = w.dot(axes.col(2));
      const double rho = (w - s * axes.col(2)).norm();
      const double tube_s = s - std::clamp(s, 0.0, length);
      double d = std::hypot(rho - radius, tube_s);
      for (int end = 0; end < 2; ++end) {
        if (!(end == 0 ? cap0 : cap1)) continue;
        const double ds = s - (end == 0 ? 0.0 : length);
        const double dr = std::max(rho - radius, 0.0);
        d = std::min(d, std::hypot(ds, dr));
      }
      return d;
    }
    case PrimitiveType::kPlane: {
      const Eigen::Vector3d l = axes.transpose() * (p - center);
      const double du = std::max(std::abs(l.x()) - half_size.x(), 0.0);
      const double dv = std::max(std::abs(l.y()) - half_size.y(), 0.0);
      return std::sqrt(l.z() * l.z() + du * du + dv * dv);
    }
  }
  return kInf;
}

Eigen::Vector3d Primitive::Normal(const Eigen::Vector3d& p) const {
  switch (type) {
    case PrimitiveType::kSphere:
      return (p - center).normalized();
    case PrimitiveType::kBox: {
      const Eigen::Vector3d q = axes.transpose() * (p - center);
      int k = 0;
      (q.cwiseAbs().cwiseQuotient(half_size)).maxCoeff(&k);
      return axes.col(k) * (q[k] < 0 ? -1.0 : 1.0);
    }
    case PrimitiveType::kCylinder: {
      const Eigen::Vector3d w = p - center;
      const double s = w.dot(axes.col(2));
      const Eigen::Vector3d radial = w - s * axes.col(2);
      const double tube = std::abs(radial.norm() - radius);
      if (cap0 && std::abs(s) < tube) return -axes.col(2);
      if (cap1 && std::abs(s - length) < tube) return axes.col(2);
      return radial.normalized();
    }
    case PrimitiveType::kPlane:
      return axes.col(2);
  }
  return Eigen::Vector3d::UnitZ();
}

bool Primitive::Intersect(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_min, double t_max,
                          double* t) const {
  return PreparedPrimitive(*this, o).Intersect(d, t_min, t_max, t);
}

PreparedPrimitive::PreparedPrimitive(const Primitive& p, const Eigen::Vector3d& o) : p_(&p) {
  switch (p.type) {
    case PrimitiveType::kSphere:
      a_ = o - p.center;
      c_ = a_.squaredNorm() - p.radius * p.radius;
      break;
    case PrimitiveType::kBox:
      a_ = p.axes.transpose() * (o - p.center);
      break;
    case PrimitiveType::kCylinder: {
      const Eigen::Vector3d w = o - p.center;
      wa_ = w.dot(p.axes.col(2));
      a_ = w - wa_ * p.axes.col(2);
      c_ = a_.squaredNorm() - p.radius * p.radius;
      break;
    }
    case PrimitiveType::kPlane: {
      const Eigen::Vector3d w = o - p.center;
      c_ = -w.dot(p.axes.col(2));
      wa_ = w.dot(p.axes.col(0));
      wv_ = w.dot(p.axes.col(1));
      break;
    }
  }
}

bool PreparedPrimitive::Intersect(const Eigen::Vector3d& d, double t_min, double t_max, double* t) const {
  const Primitive& p = *p_;
  switch (p.type) {
    case PrimitiveType::kSphere: {
      double t0, t1;
      if (!SolveQuadratic(d.squaredNorm(), a_.dot(d), c_, &t0, &t1)) return false;
      // The far root is the inside of the sphere (a camera inside a backdrop dome).
      const double r = t0 > t_min ? t0 : t1;
      if (r <= t_min || r >= t_max) return false;
      *t = r;
      return true;
    }
    case PrimitiveType::kBox: {
      const Eigen::Vector3d ld = p.axes.transpose() * d;
      double t_near = -kInf, t_far = kInf;
      for (int k = 0; k < 3; ++k) {
        const double h = p.half_size[k];
        if (ld[k] == 0) {
          if (std::abs(a_[k]) > h) return false;
          continue;
        }
        const double inv = 1.0 / ld[k];
        double ta = (-h - a_[k]) * inv, tb = (h - a_[k]) * inv;
        if (ta > tb) std::swap(ta, tb);
        t_near = std::max(t_near, ta);
        t_far = std::min(t_far, tb);
        if (t_near > t_far) return false;
      }
      const double r = t_near > t_min ? t_near : t_far;
      if (r <= t_min || r >= t_max) return false;
      *t = r;
      return true;
    }
    case PrimitiveType::kCylinder: {
      const Eigen::Vector3d& axis = p.axes.col(2);
      const double da = d.dot(axis);
      const Eigen::Vector3d dp = d - da * axis;
      double best = t_max;
      bool hit = false;
      double t0, t1;
      if (SolveQuadratic(dp.squaredNorm(), a_.dot(dp), c_, &t0, &t1)) {
        for (double r : {t0, t1}) {
          if (r <= t_min || r >= best) continue;
          const double s = wa_ + r * da;
          if (s >= 0 && s <= p.length) {
            best = r;
            hit = true;
            break;  // roots are ascending
          }
        }
      }
      if (da != 0) {
        for (int end = 0; end < 2; ++end) {
          if (!(end == 0 ? p.cap0 : p.cap1)) continue;
          const double r = ((end == 0 ? 0.0 : p.length) - wa_) / da;
          if (r <= t_min || r >= best) continue;
          if ((a_ + r * dp).squaredNorm() <= p.radius * p.radius) {
            best = r;
            hit = true;
          }
        }
      }
      if (hit) *t = best;
      return hit;
    }
    case PrimitiveType::kPlane: {
      const double dn = d.dot(p.axes.col(2));
      if (dn == 0) return false;
      const double r = c_ / dn;
      if (r <= t_min || r >= t_max) return false;
      if (std::isfinite(p.half_size.x())) {
        if (std::abs(wa_ + r * d.dot(p.axes.col(0))) > p.half_size.x()) return false;
        if (std::abs(wv_ + r * d.dot(p.axes.col(1))) > p.half_size.y()) return false;
      }
      *t = r;
      return true;
    }
  }
  return false;
}

int Scene::Add(Primitive primitive) {
  primitive.thin = primitive.ThinSize() <= thin_radius_;
  primitives_.push_back(std::move(primitive));
  return static_cast<int>(primitives_.size()) - 1;
}

void Scene::set_thin_radius(double r) {
  thin_radius_ = r;
  for (Primitive& p : primitives_) p.thin = p.ThinSize() <= thin_radius_;
}

Hit Scene::Intersect(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_min, double t_max) const {
  Hit hit;
  hit.t = t_max;
  for (int i = 0; i < NumPrimitives(); ++i) {
    double t;
    if (primitives_[i].Intersect(o, d, t_min, hit.t, &t)) {
      hit.t = t;
      hit.id = i;
    }
  }
  if (!hit.ok()) hit.t = std::numeric_limits<double>::infinity();
  return hit;
}

}  // namespace lfrecon::synth
