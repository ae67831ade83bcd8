#pragma once
// Voxel-vote depth filtering (paper §3.2, BRIEF §1.2): the foreground depths of
// all views within 15° vote in a voxel grid over V, H(v) = Σ c_x exp(-‖v-x‖² /
// 2σ_v²) (eq. 7), and each foreground pixel of the filtered view moves to the
// most-voted voxel on its viewing ray. Background depths are kept.
//
// VoteGrid holds the votes of a *set* of views and supports adding and
// removing a view, so a sliding window over the sequence costs two splats per
// step and memory stays bounded (one dense float grid over V) for any length.
#include <cstdint>
#include <map>
#include <vector>

#include "depth/depth_map.h"
#include "geometry/pinhole_view.h"
#include "geometry/triangle_mesh.h"

namespace lfrecon {

struct DepthFilterOptions {
  // Edge length of a voxel of V in metres; <= 0: derived so that V's longest
  // side has `grid_resolution` voxels.
  double voxel_size = 0.0;
  int grid_resolution = 256;
  // σ_v in voxels (eq. 7: one voxel); votes are truncated at 2.5 σ_v.
  double sigma_v_voxels = 1.0;
  // Views within this angle vote for a view (§3.2: 15°).
  double max_view_angle_deg = 15.0;
  // Minimum votes for a pixel to be moved; pixels on rays with fewer lose their depth.
  double min_votes = 1e-3;
  // Only move a pixel if the voted depth is within this factor of its own
  // (relative); further ones are removed as outliers. <= 0: no limit.
  double max_relative_move = 0.05;
  // Multiply the confidence by min(1, votes / votes_saturation) at the chosen point.
  bool confidence_from_votes = true;
  double votes_saturation = 10.0;
  void Check() const;
};

class VoteGrid {
 public:
  VoteGrid(const BoundingBox& volume, const DepthFilterOptions& options);

  double voxel_size() const { return voxel_size_; }
  Eigen::Vector3i dims() const { return dims_; }
  // Adds (sign = +1) or removes (sign = -1) the foreground votes of one view.
  void Splat(const DepthMap& map, const PinholeView& view, float sign);
  // Interpolated votes at a world point (0 outside the grid).
  float VotesAt(const Eigen::Vector3d& world) const;
  // Reassigns the foreground depths of `map` (seen from `view`) to the
  // most-voted point on each pixel's ray; returns the filtered map.
  DepthMap Filter(const DepthMap& map, const PinholeView& view) const;

 private:
  // Interpolated votes at grid coordinates (voxel k's centre at k).
  float VotesAtGrid(const Eigen::Vector3d& g) const;
  std::int64_t Index(int x, int y, int z) const {
    return (static_cast<std::int64_t>(z) * dims_.y() + y) * dims_.x() + x;
  }
  DepthFilterOptions options_;
  BoundingBox volume_;
  double voxel_size_ = 0;
  Eigen::Vector3i dims_;
  std::vector<float> votes_;
};

// Filters one view given the sparse maps of its neighbours within 15° (and itself).
// For sequences, prefer SlidingDepthFilter.
DepthMap FilterDepth(const DepthMap& map, const PinholeView& view, const std::vector<const DepthMap*>& voters,
                     const std::vector<const PinholeView*>& voter_views, const BoundingBox& volume,
                     const DepthFilterOptions& options);

}  // namespace lfrecon
