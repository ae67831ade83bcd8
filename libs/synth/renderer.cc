#include "synth/renderer.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "util/error.h"

namespace lfrecon::synth {
namespace {

constexpr double kNear = 1e-6;  // rays start 1 um in front of the camera (planar depth)
constexpr int kTile = 16;

// Per-frame ray set-up: origin, direction through a pixel, and the primitives
// whose bounding volumes can cover each 16x16 tile.
struct FrameSetup {
  Eigen::Vector3d origin;
  Eigen::Matrix3d R, Rt;
  Eigen::Vector3d t;
  double fx, fy, cx, cy, inv_fx, inv_fy;
  int width, height, tiles_x, tiles_y;
  std::vector<PreparedPrimitive> prepared;
  // Lower bound of the distance from the camera to each primitive's surface:
  // tiles list primitives in ascending order of it, so a ray stops testing once
  // its nearest hit is closer than the next bound.
  std::vector<double> min_distance;
  std::vector<double> min_distance_sq;  // squared, to compare without a square root per ray
  std::vector<int> order;               // all primitives by ascending min_distance
  std::vector<std::vector<int>> tiles;

  // World direction of the ray through image point (u, v); its camera-frame z
  // is 1, so the ray parameter equals planar depth.
  Eigen::Vector3d Direction(double u, double v) const {
    return Rt * Eigen::Vector3d((u - cx) * inv_fx, (v - cy) * inv_fy, 1.0);
  }
};

// Pixel-column and -row ranges (inclusive) that a sphere (world centre c,
// radius r) can cover; false if it is entirely behind the camera or off-image.
bool ScreenRect(const FrameSetup& f, const Eigen::Vector3d& c_world, double r, int* x0, int* x1, int* y0,
                int* y1) {
  auto full = [&] {
    *x0 = 0;
    *x1 = f.width - 1;
    *y0 = 0;
    *y1 = f.height - 1;
    return true;
  };
  if (!std::isfinite(r)) return full();
  const Eigen::Vector3d c = f.R * c_world + f.t;
  if (c.norm() <= r * (1 + 1e-9) + 1e-9) return full();  // camera inside the sphere
  if (c.z() + r <= kNear) return false;                  // entirely behind
  if (c.z() - r <= 1e-3 * r + kNear) return full();      // straddles the camera plane: be conservative
  // Tangent lines x = m z from the camera to the sphere's disc (its projection
  // on the xz- or yz-plane has the same radius).
  const double zz = c.z() * c.z() - r * r;
  auto bounds = [&](double a, double f_len, double centre, double* lo, double* hi) {
    const double s = r * std::sqrt(a * a + zz);
    *lo = f_len * (a * c.z() - s) / zz + centre;
    *hi = f_len * (a * c.z() + s) / zz + centre;
  };
  double u_lo, u_hi, v_lo, v_hi;
  bounds(c.x(), f.fx, f.cx, &u_lo, &u_hi);
  bounds(c.y(), f.fy, f.cy, &v_lo, &v_hi);
  // One pixel of margin for rounding; clamp before casting to int.
  const double big = 1e7;
  *x0 = static_cast<int>(std::floor(std::clamp(u_lo, -big, big))) - 1;
  *x1 = static_cast<int>(std::floor(std::clamp(u_hi, -big, big))) + 1;
  *y0 = static_cast<int>(std::floor(std::clamp(v_lo, -big, big))) - 1;
  *y1 = static_cast<int>(std::floor(std::clamp(v_hi, -big, big))) + 1;
  if (*x1 < 0 || *y1 < 0 || *x0 >= f.width || *y0 >= f.height) return false;
  *x0 = std::max(*x0, 0);
  *y0 = std::max(*y0, 0);
  *x1 = std::min(*x1, f.width - 1);
  *y1 = std::min(*y1, f.height - 1);
  return true;
}

// Screen rectangle of a convex hull given by its corner points: the visible
// part lies in hull ∩ {z > near}, whose projection is spanned by the corners in
// front and the points where segments between corners cross the near plane.
bool ScreenRectOfHull(const FrameSetup& f, const std::vector<Eigen::Vector3d>& corners_world, int* x0,
                      int* x1, int* y0, int* y1) {
  std::vector<Eigen::Vector3d> cam;
  cam.reserve(corners_world.size());
  for (const auto& p : corners_world) cam.push_back(f.R * p + f.t);
  const double near = kNear;
  double u_lo = std::numeric_limits<double>::infinity(), u_hi = -u_lo, v_lo = u_lo, v_hi = -u_lo;
  bool any = false;
  auto add = [&](const Eigen::Vector3d& p) {
    const double u = f.fx * p.x() / p.z() + f.cx, v = f.fy * p.y() / p.z() + f.cy;
    u_lo = std::min(u_lo, u);
    u_hi = std::max(u_hi, u);
    v_lo = std::min(v_lo, v);
    v_hi = std::max(v_hi, v);
    any = true;
  };
  for (std::size_t a = 0; a < cam.size(); ++a) {
    if (cam[a].z() > near) add(cam[a]);
    for (std::size_t b = a + 1; b < cam.size(); ++b) {
      const double za = cam[a].z() - near, zb = cam[b].z() - near;
      if ((za > 0) == (zb > 0)) continue;
      const double s = za / (za - zb);
      Eigen::Vector3d p = cam[a] + s * (cam[b] - cam[a]);
      p.z() = near;
      add(p);
    }
  }
  if (!any) return false;
  const double big = 1e7;
  *x0 = static_cast<int>(std::floor(std::clamp(u_lo, -big, big))) - 1;
  *x1 = static_cast<int>(std::floor(std::clamp(u_hi, -big, big))) + 1;
  *y0 = static_cast<int>(std::floor(std::clamp(v_lo, -big, big))) - 1;
  *y1 = static_cast<int>(std::floor(std::clamp(v_hi, -big, big))) + 1;
  if (*x1 < 0 || *y1 < 0 || *x0 >= f.width || *y0 >= f.height) return false;
  *x0 = std::max(*x0, 0);
  *y0 = std::max(*y0, 0);
  *x1 = std::min(*x1, f.width - 1);
  *y1 = std::min(*y1, f.height - 1);
  return true;
}

// Corners of a primitive's oriented bounding box (empty for spheres and infinite planes).
std::vector<Eigen::Vector3d> HullCorners(const Primitive& p) {
  std::vector<Eigen::Vector3d> out;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero(), half = Eigen::Vector3d::Zero();
  switch (p.type) {
    case PrimitiveType::kSphere:
      return out;
    case PrimitiveType::kBox:
      centre = p.center;
      half = p.half_size;
      break;
    case PrimitiveType::kCylinder:
      centre = p.center + 0.5 * p.length * p.axes.col(2);
      half = Eigen::Vector3d(p.radius, p.radius, 0.5 * p.length);
      break;
    case PrimitiveType::kPlane:
      if (!p.IsBounded()) return out;
      centre = p.center;
      half = Eigen::Vector3d(p.half_size.x(), p.half_size.y(), 0);
      break;
  }
  for (int k = 0; k < 8; ++k) {
    const Eigen::Vector3d sign((k & 1) ? 1 : -1, (k & 2) ? 1 : -1, (k & 4) ? 1 : -1);
    out.push_back(centre + p.axes * sign.cwiseProduct(half));
  }
  return out;
}

// A lower bound of |X - o| over the surface points X of p.
double MinDistance(const Primitive& p, const Eigen::Vector3d& o) {
  Eigen::Vector3d c;
  double r;
  p.BoundingSphere(&c, &r);
  const double d = (o - c).norm();
  double bound = std::isfinite(r) ? std::max(d - r, 0.0) : 0.0;
  if (p.type == PrimitiveType::kSphere && d < r) bound = r - d;  // inside a dome
  if (p.type == PrimitiveType::kPlane) bound = std::max(bound, std::abs((o - p.center).dot(p.axes.col(2))));
  // Shrink a little so rounding never skips a true nearest hit; never negative
  // (the renderer compares squares).
  return std::max(bound * (1 - 1e-9) - 1e-9, 0.0);
}

FrameSetup MakeFrameSetup(const Scene& scene, const PinholeView& view, bool with_tiles) {
  FrameSetup f;
  f.R = view.R;
  f.Rt = view.R.transpose();
  f.t = view.t;
  f.origin = view.Center();
  f.fx = view.K(0, 0);
  f.fy = view.K(1, 1);
  f.cx = view.K(0, 2);
  f.cy = view.K(1, 2);
  f.inv_fx = 1.0 / f.fx;
  f.inv_fy = 1.0 / f.fy;
  f.width = view.width;
  f.height = view.height;
  f.prepared.reserve(static_cast<std::size_t>(scene.NumPrimitives()));
  for (const Primitive& p : scene.primitives()) f.prepared.emplace_back(p, f.origin);
  f.min_distance.resize(static_cast<std::size_t>(scene.NumPrimitives()));
  f.order.resize(static_cast<std::size_t>(scene.NumPrimitives()));
  for (int id = 0; id < scene.NumPrimitives(); ++id) {
    f.min_distance[id] = MinDistance(scene.primitive(id), f.origin);
    f.min_distance_sq.push_back(f.min_distance[id] * f.min_distance[id]);
    f.order[id] = id;
  }
  std::stable_sort(f.order.begin(), f.order.end(),
                   [&](int a, int b) { return f.min_distance[a] < f.min_distance[b]; });
  if (!with_tiles) return f;
  f.tiles_x = (f.width + kTile - 1) / kTile;
  f.tiles_y = (f.height + kTile - 1) / kTile;
  f.tiles.assign(static_cast<std::size_t>(f.tiles_x) * f.tiles_y, {});
  for (int id : f.order) {
    const Primitive& p = scene.primitive(id);
    int x0, x1, y0, y1;
    if (p.type == PrimitiveType::kSphere || !p.IsBounded()) {
      Eigen::Vector3d c;
      double r;
      p.BoundingSphere(&c, &r);
      if (!ScreenRect(f, c, r, &x0, &x1, &y0, &y1)) continue;
    } else if (!ScreenRectOfHull(f, HullCorners(p), &x0, &x1, &y0, &y1)) {
      continue;
    }
    for (int ty = y0 / kTile; ty <= y1 / kTile; ++ty)
      for (int tx = x0 / kTile; tx <= x1 / kTile; ++tx)
        f.tiles[static_cast<std::size_t>(ty) * f.tiles_x + tx].push_back(id);
  }
  return f;
}

inline Hit Trace(const FrameSetup& f, const std::vector<int>& candidates, const Eigen::Vector3d& d) {
  Hit hit;
  double best = std::numeric_limits<double>::infinity();
  const double d_sq = d.squaredNorm();
  for (int id : candidates) {
    // Sorted ascending: no later primitive can be nearer than the hit we have.
    if (f.min_distance_sq[static_cast<std::size_t>(id)] >= best * best * d_sq) break;
    double t;
    if (f.prepared[static_cast<std::size_t>(id)].Intersect(d, kNear, best, &t)) {
      best = t;
      hit.id = id;
    }
  }
  if (hit.ok()) hit.t = best;
  return hit;
}

// Albedo at a hit, pre-filtered over the sample's footprint: `scale` * depth
// across the ray, stretched by 1 / cos(incidence) along the slope; the
// isotropic filter takes their geometric mean (between blur and aliasing).
inline Eigen::Vector3f Shade(const Scene& scene, const FrameSetup& f, const Hit& hit,
                             const Eigen::Vector3d& d, double scale) {
  const Eigen::Vector3d x = f.origin + hit.t * d;
  const Primitive& p = scene.primitive(hit.id);
  double filter = 0;
  if (scale > 0 && p.material.IsTextured()) {
    const double cos_incidence = std::abs(p.Normal(x).dot(d)) / d.norm();
    filter = scale * hit.t / std::sqrt(std::max(cos_incidence, 0.02));
  }
  return p.material.Albedo(x, filter);
}

// Counter-based stream of Gaussian numbers (splitmix64 + Box-Muller), one per
// image row, so noise does not depend on how rows are spread over threads.
class RowNoise {
 public:
  explicit RowNoise(std::uint64_t seed) : state_(seed) {}
  double Gauss() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    double u1 = HashToUnit(Next());
    const double u2 = HashToUnit(Next());
    if (u1 < 1e-300) u1 = 1e-300;
    const double rad = std::sqrt(-2.0 * std::log(u1));
    spare_ = rad * std::sin(2.0 * M_PI * u2);
    has_spare_ = true;
    return rad * std::cos(2.0 * M_PI * u2);
  }

 private:
  std::uint64_t Next() { return HashCombine(state_, ++counter_); }
  std::uint64_t state_;
  std::uint64_t counter_ = 0;
  double spare_ = 0;
  bool has_spare_ = false;
};

}  // namespace

void RenderOptions::Check() const {
  LFRECON_CHECK_OPTION(supersampling >= 1 && supersampling <= 16);
  LFRECON_CHECK_OPTION(std::isfinite(noise_sigma) && noise_sigma >= 0);
}

RenderResult Render(const Scene& scene, const PinholeView& view, const RenderOptions& options,
                    std::uint64_t noise_seed) {
  options.Check();
  if (view.width <= 0 || view.height <= 0) throw OptionError("synth: render size must be positive");
  const FrameSetup f = MakeFrameSetup(scene, view, true);
  const int W = f.width, H = f.height, S = options.supersampling;
  const bool centre_in_grid = (S % 2 == 1) && !options.jitter;
  const int centre_sample = centre_in_grid ? (S / 2) * S + S / 2 : -1;
  const float inv_samples = 1.0f / static_cast<float>(S * S);
  const Eigen::Vector3f background = scene.background_color();
  const std::uint64_t jitter_seed = HashCombine(noise_seed, 0x6A177E5ull);
  // Texture filter width per unit planar depth: one pixel, or one sample.
  const double pixel_scale = options.texture_filter ? 1.0 / std::min(f.fx, f.fy) : 0.0;
  const double sample_scale = pixel_scale / S;
  const bool point_pixels = options.adaptive && options.texture_filter;

  RenderResult out;
  out.image.create(H, W, CV_32FC3);
  out.depth.create(H, W, CV_64F);
  out.labels.create(H, W, CV_32S);
  out.mixed.create(H, W, CV_8U);

  tbb::parallel_for(tbb::blocked_range<int>(0, f.tiles_y), [&](const tbb::blocked_range<int>& range) {
    std::vector<double> grid(static_cast<std::size_t>(S));
    for (int k = 0; k < S; ++k) grid[k] = (k + 0.5) / S;
    std::vector<Hit> hits(static_cast<std::size_t>(S * S));
    std::vector<Eigen::Vector3d> dirs(static_cast<std::size_t>(S * S));
    for (int ty = range.begin(); ty != range.end(); ++ty) {
      const int r_end = std::min(H, (ty + 1) * kTile);
      for (int r = ty * kTile; r < r_end; ++r) {
        auto* img = out.image.ptr<cv::Vec3f>(r);
        auto* dep = out.depth.ptr<double>(r);
        auto* lab = out.labels.ptr<int>(r);
        auto* mix = out.mixed.ptr<std::uint8_t>(r);
        for (int c = 0; c < W; ++c) {
          const std::vector<int>& cand = f.tiles[static_cast<std::size_t>(ty) * f.tiles_x + c / kTile];
          const std::uint64_t pixel_hash =
              options.jitter ? HashCombine(jitter_seed, static_cast<std::uint64_t>(r) * W + c) : 0;
          bool mixed = false;
          for (int sy = 0; sy < S; ++sy) {
            for (int sx = 0; sx < S; ++sx) {
              double u = c + grid[sx], v = r + grid[sy];
              if (options.jitter) {
                const std::uint64_t h = HashCombine(pixel_hash, static_cast<std::uint64_t>(sy * S + sx));
                u = c + (sx + HashToUnit(h)) / S;
                v = r + (sy + HashToUnit(HashCombine(h, 1))) / S;
              }
              const int k = sy * S + sx;
              dirs[k] = f.Direction(u, v);
              hits[k] = Trace(f, cand, dirs[k]);
              if (hits[k].id != hits[0].id) mixed = true;
            }
          }
          Hit centre;
          Eigen::Vector3d centre_dir;
          if (centre_in_grid) {
            centre = hits[centre_sample];
            centre_dir = dirs[centre_sample];
          } else {
            centre_dir = f.Direction(c + 0.5, r + 0.5);
            centre = Trace(f, cand, centre_dir);
          }
          Eigen::Vector3f colour;
          if (!mixed && point_pixels && centre.id == hits[0].id) {
            colour = centre.ok() ? Shade(scene, f, centre, centre_dir, pixel_scale) : background;
          } else {
            colour.setZero();
            for (int k = 0; k < S * S; ++k)
              colour += hits[k].ok() ? Shade(scene, f, hits[k], dirs[k], sample_scale) : background;
            colour *= inv_samples;
          }
          img[c] = cv::Vec3f(colour.z(), colour.y(), colour.x());  // RGB -> BGR
          dep[c] = centre.ok() ? centre.t : 0.0;
          lab[c] = centre.id;
          mix[c] = mixed ? 255 : 0;
        }
        if (options.noise_sigma > 0 || options.quantize) {
          RowNoise noise(HashCombine(noise_seed, static_cast<std::uint64_t>(r)));
          float* px = out.image.ptr<float>(r);
          for (int k = 0; k < 3 * W; ++k) {
            double v = px[k];
            if (options.noise_sigma > 0) v += options.noise_sigma * noise.Gauss();
            v = std::clamp(v, 0.0, 1.0);
            if (options.quantize) v = std::round(v * 255.0) / 255.0;
            px[k] = static_cast<float>(v);
          }
        }
      }
    }
  });
  return out;
}

Hit CastPixel(const Scene& scene, const PinholeView& view, const Eigen::Vector2d& pixel) {
  const FrameSetup f = MakeFrameSetup(scene, view, false);
  return Trace(f, f.order, f.Direction(pixel.x(), pixel.y()));
}

namespace {
cv::Mat MaskWhere(const Scene& scene, const cv::Mat& labels, bool thin) {
  CV_Assert(labels.type() == CV_32S);
  cv::Mat mask(labels.size(), CV_8U, cv::Scalar(0));
  for (int r = 0; r < labels.rows; ++r) {
    const int* l = labels.ptr<int>(r);
    auto* m = mask.ptr<std::uint8_t>(r);
    for (int c = 0; c < labels.cols; ++c) {
      if (l[c] < 0 || l[c] >= scene.NumPrimitives()) continue;
      const Primitive& p = scene.primitive(l[c]);
      if (thin ? p.thin : p.foreground) m[c] = 255;
    }
  }
  return mask;
}
}  // namespace

cv::Mat ForegroundMask(const Scene& scene, const cv::Mat& labels) { return MaskWhere(scene, labels, false); }
cv::Mat ThinMask(const Scene& scene, const cv::Mat& labels) { return MaskWhere(scene, labels, true); }

cv::Mat DepthToFloat(const cv::Mat& depth) {
  cv::Mat out;
  depth.convertTo(out, CV_32F);
  return out;
}

}  // namespace lfrecon::synth
