#include "depth/depth_filter.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "util/error.h"

namespace lfrecon {

void DepthFilterOptions::Check() const {
  LFRECON_CHECK_OPTION(voxel_size >= 0);
  LFRECON_CHECK_OPTION(voxel_size > 0 || (grid_resolution >= 8 && grid_resolution <= 2048));
  LFRECON_CHECK_OPTION(sigma_v_voxels > 0);
  LFRECON_CHECK_OPTION(max_view_angle_deg > 0);
  LFRECON_CHECK_OPTION(min_votes >= 0);
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
  const double inv_two_sigma2 = 1.0 / (2.0 * sigma * sigma);
  // Serial over pixels: splats overlap, and one view's splat is cheap next to depth estimation.
  for (int r = 0; r < map.depth.rows; ++r) {
    const float* d = map.depth.ptr<float>(r);
    const float* c = map.confidence.ptr<float>(r);
    const std::uint8_t* l = map.label.ptr<std::uint8_t>(r);
    for (int col = 0; col < map.depth.cols; ++col) {
      if (!(d[col] > 0) || l[col] != static_cast<std::uint8_t>(DepthLabel::kForeground) || !(c[col] > 0)) continue;
      const Eigen::Vector3d x = view.Unproject(Eigen::Vector2d(col + 0.5, r + 0.5), d[col]);
      // Grid coordinates: voxel k's centre is at min + (k + 0.5) * size.
      const Eigen::Vector3d g = (x - volume_.min) / voxel_size_ - Eigen::Vector3d::Constant(0.5);
      const int cx = static_cast<int>(std::lround(g.x())), cy = static_cast<int>(std::lround(g.y())),
                cz = static_cast<int>(std::lround(g.z()));
      for (int z = std::max(0, cz - radius); z <= std::min(dims_.z() - 1, cz + radius); ++z)
        for (int y = std::max(0, cy - radius); y <= std::min(dims_.y() - 1, cy + radius); ++y)
          for (int xx = std::max(0, cx - radius); xx <= std::min(dims_.x() - 1, cx + radius); ++xx) {
            const double d2 = (Eigen::Vector3d(xx, y, z) - g).squaredNorm();
            votes_[Index(xx, y, z)] += sign * c[col] * static_cast<float>(std::exp(-d2 * inv_two_sigma2));
          }
    }
  }
}

float VoteGrid::VotesAt(const Eigen::Vector3d& world) const {
  const Eigen::Vector3d g = (world - volume_.min) / voxel_size_ - Eigen::Vector3d::Constant(0.5);
  const int x0 = static_cast<int>(std::floor(g.x())), y0 = static_cast<int>(std::floor(g.y())),
            z0 = static_cast<int>(std::floor(g.z()));
  float sum = 0;
  const double fx = g.x() - x0, fy = g.y() - y0, fz = g.z() - z0;
  for (int k = 0; k < 8; ++k) {
    const int x = x0 + (k & 1), y = y0 + ((k >> 1) & 1), z = z0 + ((k >> 2) & 1);
    if (x < 0 || y < 0 || z < 0 || x >= dims_.x() || y >= dims_.y() || z >= dims_.z()) continue;
    const double w = ((k & 1) ? fx : 1 - fx) * (((k >> 1) & 1) ? fy : 1 - fy) * (((k >> 2) & 1) ? fz : 1 - fz);
    sum += static_cast<float>(w) * votes_[Index(x, y, z)];
  }
  return sum;
}

DepthMap VoteGrid::Filter(const DepthMap& map, const PinholeView& view) const {
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
        // March the ray in steps of half a voxel (in depth along the ray's z).
        const Eigen::Vector3d dir = view.Unproject(p, 1.0) - view.Unproject(p, 0.0);  // world per unit depth
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
          const float v = VotesAt(view.Unproject(p, z));
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
              map.confidence.at<float>(r, col) * std::min(1.0f, best / static_cast<float>(options_.votes_saturation));
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
  return grid.Filter(map, view);
}

}  // namespace lfrecon
