#pragma once
// Scenes of analytic primitives for the synthetic dense light-field generator:
// spheres, oriented boxes, capped (or open) cylinders with any axis, and
// infinite or bounded planes. Every primitive carries a material and two flags
// that the tests use as ground truth: `foreground` (it lies inside the scene's
// foreground box V) and `thin` (its radius is at most the scene's thin_radius).
// Ray casting is exact in double precision; a ray's parameter t is the planar
// depth when its direction has camera-frame z = 1.
#include <Eigen/Core>
#include <limits>
#include <string>
#include <vector>

#include "geometry/triangle_mesh.h"
#include "synth/texture.h"

namespace lfrecon::synth {

enum class PrimitiveType { kSphere, kBox, kCylinder, kPlane };

std::string PrimitiveTypeName(PrimitiveType type);

struct Primitive {
  PrimitiveType type = PrimitiveType::kSphere;
  std::string name;
  Material material;
  bool foreground = false;
  bool thin = false;  // set by Scene::Add from the scene's thin_radius

  // Geometry; which fields apply depends on `type`:
  //  sphere:   center, radius
  //  box:      center, axes (columns: the box's unit x, y, z in world), half_size
  //  cylinder: center = base point p0, axes.col(2) = unit axis, length, radius, cap0 (at p0), cap1 (at p1)
  //  plane:    center = a point on it, axes.col(0/1) in-plane unit u, v, axes.col(2) = normal,
  //            half_size.x/y = half extents along u, v (infinity: unbounded)
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  Eigen::Matrix3d axes = Eigen::Matrix3d::Identity();
  Eigen::Vector3d half_size = Eigen::Vector3d::Zero();
  double radius = 0;
  double length = 0;
  bool cap0 = true;
  bool cap1 = true;

  static Primitive Sphere(const Eigen::Vector3d& center, double radius, const Material& material);
  // `axes`: a rotation whose columns are the box's local axes in world coordinates.
  static Primitive Box(const Eigen::Vector3d& center, const Eigen::Vector3d& half_size,
                       const Material& material, const Eigen::Matrix3d& axes = Eigen::Matrix3d::Identity());
  // A cylinder from p0 to p1; an open end (cap = false) shows the inside, like a cup.
  static Primitive Cylinder(const Eigen::Vector3d& p0, const Eigen::Vector3d& p1, double radius,
                            const Material& material, bool cap0 = true, bool cap1 = true);
  // An infinite plane through `point` with the given normal.
  static Primitive Plane(const Eigen::Vector3d& point, const Eigen::Vector3d& normal,
                         const Material& material);
  // A bounded rectangle centred at `center`, spanned by (orthogonalised) u and v,
  // half extents half_u, half_v; normal u x v.
  static Primitive Rect(const Eigen::Vector3d& center, const Eigen::Vector3d& u, const Eigen::Vector3d& v,
                        double half_u, double half_v, const Material& material);

  Primitive& Named(std::string n) {
    name = std::move(n);
    return *this;
  }
  Primitive& Foreground(bool f = true) {
    foreground = f;
    return *this;
  }

  bool IsBounded() const;
  Eigen::Vector3d CylinderEnd() const { return center + length * axes.col(2); }
  // Smallest-ish sphere around the primitive (radius infinity for unbounded planes).
  void BoundingSphere(Eigen::Vector3d* sphere_center, double* sphere_radius) const;
  // Unsigned distance from p to the primitive's surface (0 on it).
  double SurfaceDistance(const Eigen::Vector3d& p) const;
  // Unit outward normal at a surface point p (planes: axes.col(2)).
  Eigen::Vector3d Normal(const Eigen::Vector3d& p) const;
  // Nearest intersection of o + t d with t in (t_min, t_max); d need not be unit.
  bool Intersect(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_min, double t_max,
                 double* t) const;
  // "Radius" used for the thin flag: sphere/cylinder radius, a box's second-smallest
  // half size (stick-like boxes), infinity for planes.
  double ThinSize() const;
};

// A primitive prepared for many rays from one origin (a camera centre): the
// origin-dependent terms are computed once per frame.
class PreparedPrimitive {
 public:
  PreparedPrimitive() = default;
  PreparedPrimitive(const Primitive& primitive, const Eigen::Vector3d& origin);
  bool Intersect(const Eigen::Vector3d& d, double t_min, double t_max, double* t) const;

 private:
  const Primitive* p_ = nullptr;
  Eigen::Vector3d a_ = Eigen::Vector3d::Zero();  // sphere: o - c; box: local origin; cylinder: w_perp
  double c_ = 0;                                 // sphere/cylinder: constant term; plane: (p - o).n
  double wa_ = 0;                                // cylinder: (o - p0).axis; plane: local u of o
  double wv_ = 0;                                // plane: local v of o
};

struct Hit {
  double t = std::numeric_limits<double>::infinity();
  int id = -1;  // primitive index, -1 for none
  bool ok() const { return id >= 0; }
};

class Scene {
 public:
  explicit Scene(std::string name = "custom") : name_(std::move(name)) {}

  // Adds a primitive (its `thin` flag is set from thin_radius) and returns its id.
  int Add(Primitive primitive);

  const std::string& name() const { return name_; }
  void set_name(std::string name) { name_ = std::move(name); }
  const std::vector<Primitive>& primitives() const { return primitives_; }
  const Primitive& primitive(int id) const { return primitives_.at(static_cast<std::size_t>(id)); }
  int NumPrimitives() const { return static_cast<int>(primitives_.size()); }

  // The foreground volume V (world, metres). Foreground primitives lie inside it,
  // background ones outside.
  const BoundingBox& foreground_bbox() const { return foreground_bbox_; }
  void set_foreground_bbox(const BoundingBox& box) { foreground_bbox_ = box; }
  // Primitives with ThinSize() <= thin_radius are thin (default 6 mm, as figurines' gt_thin).
  double thin_radius() const { return thin_radius_; }
  void set_thin_radius(double r);
  // Colour (RGB) of rays that hit nothing.
  const Eigen::Vector3f& background_color() const { return background_color_; }
  void set_background_color(const Eigen::Vector3f& c) { background_color_ = c; }

  // Nearest hit of o + t d, t in (t_min, t_max), over all primitives.
  Hit Intersect(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_min = 0,
                double t_max = std::numeric_limits<double>::infinity()) const;
  Eigen::Vector3f Albedo(int id, const Eigen::Vector3d& p, double filter = 0) const {
    return primitive(id).material.Albedo(p, filter);
  }

 private:
  std::string name_;
  std::vector<Primitive> primitives_;
  BoundingBox foreground_bbox_;
  double thin_radius_ = 0.006;
  Eigen::Vector3f background_color_{0.5f, 0.5f, 0.5f};
};

}  // namespace lfrecon::synth
