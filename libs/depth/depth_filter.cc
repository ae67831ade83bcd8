#include "depth/depth_filter.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "geometry/rigid3.h"
#include "util/error.h"

namespace lfrecon {

void DepthFilterOptions::Check() const {
  LFRECON_CHECK_OPTION(voxel_size >= 0);
  LFRECON_CHECK_OPTION(voxel_size > 0 || (grid_resolution >= 8 && grid_resolution <= 2048));
  LFRECON_CHECK_OPTION(sigma_v_voxels > 0);
  LFRECON_CHECK_OPTION(max_view_angle_deg > 0);
  LFRECON_CHECK_OPTION(min_votes >= 0);
  LFRECON_CHECK_OPTION(!confidence_from_votes || votes_saturation_per_view > 0);
}

VoteGrid::VoteGrid(const BoundingBox& volume, const DepthFilterOptions& options) : options_(options), volume_(volume) {
  options_.Check();
  if (!volume.IsValid()) throw OptionError("VoteGrid: the volume V is empty or not finite");
  voxel_size_ = options.voxel_size > 0 ? options.voxel_size : volume.Extent().maxCoeff() / options.grid_resolution;
  for (int k = 0; k < 3; ++k) dims_[k] = std::max(1, static_cast<int>(std::ceil(volume.Extent()[k] / voxel_size_)));
  const std::int64_t n = static_cast<std::int64_t>(dims_.x()) * dims_.y() * dims_.z();
  if (n > (std::int64_t(1) << 31)) throw OptionError("VoteGrid: voxel size too small for V (over 2^31 voxels)");
  votes_.assign(n, 0.0f);
}

void VoteGrid::Splat(const DepthMap& map, const PinholeView& view, float sign) {
  const double sigma = options_.sigma_v_voxels;  // in voxels
  const int radius = static_cast<int>(std::ceil(2.5 * sigma));
  const int width = 2 * radius + 1;
  const double inv_two_sigma2 = 1.0 / (2.0 * sigma * sigma);
  // The Gaussian is separable: exp(-‖v-x‖²/2σ²) = Π_k exp(-(v_k-x_k)²/2σ²), so a
  // point needs 3 × width exponentials instead of width³, and the innermost
  // loop runs over a contiguous row of voxels (it vectorises).
  struct Point {
    int lo[3];     // first voxel of the point's (clipped) cube on each axis
    int count[3];  // its voxels on each axis
  };
  std::vector<Point> points;
  std::vector<float> weights;  // 3 × width per point: x, y, z weights (z ones × sign × confidence)
  const Eigen::Vector3i dims = dims_;
  for (int r = 0; r < map.depth.rows; ++r) {
    const float* d = map.depth.ptr<float>(r);
    const float* c = map.confidence.ptr<float>(r);
    const std::uint8_t* l = map.label.ptr<std::uint8_t>(r);
    for (int col = 0; col < map.depth.cols; ++col) {
      if (!(d[col] > 0) || l[col] != static_cast<std::uint8_t>(DepthLabel::kForeground) || !(c[col] > 0)) continue;
      const Eigen::Vector3d x = view.Unproject(Eigen::Vector2d(col + 0.5, r + 0.5), d[col]);
      // Grid coordinates: voxel k's centre is at min + (k + 0.5) * size.
      const Eigen::Vector3d g = (x - volume_.min) / voxel_size_ - Eigen::Vector3d::Constant(0.5);
      Point pt;
      bool inside = true;
      for (int k = 0; k < 3 && inside; ++k) {
        const int ck = static_cast<int>(std::lround(g[k]));
        pt.lo[k] = std::max(0, ck - radius);
        pt.count[k] = std::min(dims[k] - 1, ck + radius) - pt.lo[k] + 1;
        inside = pt.count[k] > 0;
      }
      if (!inside) continue;
      const size_t base = weights.size();
      weights.resize(base + 3 * width);
      for (int k = 0; k < 3; ++k)
        for (int v = 0; v < pt.count[k]; ++v) {
          const double dv = pt.lo[k] + v - g[k];
          weights[base + k * width + v] =
              static_cast<float>(std::exp(-dv * dv * inv_two_sigma2) * (k == 2 ? sign * c[col] : 1.0f));
        }
      points.push_back(pt);
    }
  }
  // Parallel over slabs of z: every task visits all points but writes only
  // its own slab, so each voxel gets its votes in pixel order whatever the
  // number of threads (deterministic, no atomics).
  const std::int64_t plane = static_cast<std::int64_t>(dims.x()) * dims.y();
  tbb::parallel_for(tbb::blocked_range<int>(0, dims.z(), 4), [&](const tbb::blocked_range<int>& slab) {
    for (size_t q = 0; q < points.size(); ++q) {
      const Point& pt = points[q];
      const int z0 = std::max(pt.lo[2], slab.begin()), z1 = std::min(pt.lo[2] + pt.count[2], slab.end());
      if (z0 >= z1) continue;
      const float* wx = &weights[q * 3 * width];
      const float* wy = wx + width;
      const float* wz = wy + width;
      const int nx = pt.count[0];
      for (int z = z0; z < z1; ++z) {
        float* slice = votes_.data() + z * plane + static_cast<std::int64_t>(pt.lo[1]) * dims.x() + pt.lo[0];
        const float wzz = wz[z - pt.lo[2]];
        for (int y = 0; y < pt.count[1]; ++y) {
          const float w = wzz * wy[y];
          float* row = slice + static_cast<std::int64_t>(y) * dims.x();
          for (int x = 0; x < nx; ++x) row[x] += w * wx[x];
        }
      }
    }
  });
}

float VoteGrid::VotesAt(const Eigen::Vector3d& world) const {
  return VotesAtGrid((world - volume_.min) / voxel_size_ - Eigen::Vector3d::Constant(0.5));
}

float VoteGrid::VotesAtGrid(const Eigen::Vector3d& g) const {
  if (g.x() >= 0 && g.y() >= 0 && g.z() >= 0 && g.x() < dims_.x() - 1 && g.y() < dims_.y() - 1 &&
      g.z() < dims_.z() - 1) {
    // Inside: truncation is floor, and the 8 corners need no bounds checks.
    const int x0 = static_cast<int>(g.x()), y0 = static_cast<int>(g.y()), z0 = static_cast<int>(g.z());
    const float fx = static_cast<float>(g.x() - x0), fy = static_cast<float>(g.y() - y0),
                fz = static_cast<float>(g.z() - z0);
    const float* v = votes_.data() + Index(x0, y0, z0);
    const std::int64_t dy = dims_.x(), dz = static_cast<std::int64_t>(dims_.x()) * dims_.y();
    const float c00 = v[0] + fx * (v[1] - v[0]), c10 = v[dy] + fx * (v[dy + 1] - v[dy]);
    const float c01 = v[dz] + fx * (v[dz + 1] - v[dz]), c11 = v[dz + dy] + fx * (v[dz + dy + 1] - v[dz + dy]);
    const float c0 = c00 + fy * (c10 - c00), c1 = c01 + fy * (c11 - c01);
    return c0 + fz * (c1 - c0);
  }
  const int x0 = static_cast<int>(std::floor(g.x())), y0 = static_cast<int>(std::floor(g.y())),
            z0 = static_cast<int>(std::floor(g.z()));
  const float fx = static_cast<float>(g.x() - x0), fy = static_cast<float>(g.y() - y0),
              fz = static_cast<float>(g.z() - z0);
  float sum = 0;
  for (int k = 0; k < 8; ++k) {
    const int x = x0 + (k & 1), y = y0 + ((k >> 1) & 1), z = z0 + ((k >> 2) & 1);
    if (x < 0 || y < 0 || z < 0 || x >= dims_.x() || y >= dims_.y() || z >= dims_.z()) continue;
    const float w = ((k & 1) ? fx : 1 - fx) * (((k >> 1) & 1) ? fy : 1 - fy) * (((k >> 2) & 1) ? fz : 1 - fz);
    sum += w * votes_[Index(x, y, z)];
  }
  return sum;
}

double FullWindowViews(const std::vector<Eigen::Vector3d>& voters, double max_view_angle_deg) {
  const double n = static_cast<double>(voters.size());
  std::vector<double> steps;
  for (std::size_t k = 1; k < voters.size(); ++k)
    steps.push_back(AngleBetweenDeg(voters[k], voters[k - 1]));
  if (steps.empty()) return std::max(1.0, n);
  std::nth_element(steps.begin(), steps.begin() + steps.size() / 2, steps.end());
  const double step = steps[steps.size() / 2];
  if (!(step > 1e-9)) return std::max(1.0, n);
  return std::max(n, 1.0 + 2.0 * max_view_angle_deg / step);
}

DepthMap VoteGrid::Filter(const DepthMap& map, const PinholeView& view, double window_views) const {
  const float saturation = static_cast<float>(options_.votes_saturation_per_view * std::max(1.0, window_views));
  DepthMap out;
  out.depth = map.depth.clone();
  out.confidence = map.confidence.clone();
  out.label = map.label.clone();
  // Planar-depth interval of V seen from this view bounds the ray march.
  double zmin, zmax;
  PlanarDepthRange(view, volume_, &zmin, &zmax);
  zmin = std::max(zmin, 1e-6);
  tbb::parallel_for(tbb::blocked_range<int>(0, map.depth.rows), [&](const tbb::blocked_range<int>& range) {
    for (int r = range.begin(); r != range.end(); ++r) {
      for (int col = 0; col < map.depth.cols; ++col) {
        if (map.label.at<std::uint8_t>(r, col) != static_cast<std::uint8_t>(DepthLabel::kForeground)) continue;
        const float d0 = map.depth.at<float>(r, col);
        const Eigen::Vector2d p(col + 0.5, r + 0.5);
        // The ray in grid coordinates is linear in depth: g(z) = g0 + z·gd.
        const Eigen::Vector3d w0 = view.Unproject(p, 0.0);
        const Eigen::Vector3d dir = view.Unproject(p, 1.0) - w0;  // world per unit depth
        const Eigen::Vector3d g0 = (w0 - volume_.min) / voxel_size_ - Eigen::Vector3d::Constant(0.5);
        const Eigen::Vector3d gd = dir / voxel_size_;
        // March the ray in steps of half a voxel (in depth along the ray's z).
        const double step = 0.5 * voxel_size_ / dir.norm();
        double lo = zmin, hi = zmax;
        if (options_.max_relative_move > 0) {
          lo = std::max(lo, d0 * (1.0 - options_.max_relative_move));
          hi = std::min(hi, d0 * (1.0 + options_.max_relative_move));
        }
        float best = -1;
        double best_d = 0;
        float prev = 0;
        double best_prev = 0, best_next = 0;
        bool want_next = false;
        for (double z = lo; z <= hi; z += step) {
          const float v = VotesAtGrid(g0 + z * gd);
          if (want_next) {
            best_next = v;
            want_next = false;
          }
          if (v > best) {
            best = v;
            best_d = z;
            best_prev = prev;
            want_next = true;
            best_next = v;
          }
          prev = v;
        }
        if (best < options_.min_votes) {
          out.depth.at<float>(r, col) = 0;
          out.confidence.at<float>(r, col) = 0;
          out.label.at<std::uint8_t>(r, col) = static_cast<std::uint8_t>(DepthLabel::kNone);
          continue;
        }
        // Parabolic refinement of the peak between its two samples.
        const double denom = best_prev - 2.0 * best + best_next;
        double offset = 0;
        if (denom < 0) offset = std::clamp(0.5 * (best_prev - best_next) / denom, -0.5, 0.5);
        out.depth.at<float>(r, col) = static_cast<float>(best_d + offset * step);
        // Multi-view support of the chosen point joins the pixel's own confidence.
        if (options_.confidence_from_votes)
          out.confidence.at<float>(r, col) =
              map.confidence.at<float>(r, col) * std::min(1.0f, best / saturation);
      }
    }
  });
  return out;
}

DepthMap FilterDepth(const DepthMap& map, const PinholeView& view, const std::vector<const DepthMap*>& voters,
                     const std::vector<const PinholeView*>& voter_views, const BoundingBox& volume,
                     const DepthFilterOptions& options) {
  VoteGrid grid(volume, options);
  for (size_t k = 0; k < voters.size(); ++k) grid.Splat(*voters[k], *voter_views[k], 1.0f);
  std::vector<Eigen::Vector3d> dirs;
  for (const PinholeView* v : voter_views) dirs.push_back(v->ViewingDirection());
  return grid.Filter(map, view, FullWindowViews(dirs, options.max_view_angle_deg));
}

}  // namespace lfrecon
