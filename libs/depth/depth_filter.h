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
  // Multiply the confidence by min(1, votes / saturation) at the chosen point,
  // saturation = votes_saturation_per_view x FullWindowViews (the views a
  // window of max_view_angle_deg on both sides holds at the voters' spacing):
  // support from a quarter of such a window counts in full, however densely
  // the views are spaced. (It was an absolute 10 votes, a quarter of the
  // figurines' 41 voting views at 0.75°: with every second view voting (1.5°)
  // the same part got half the confidence; figurines thin recall@5mm 0.886
  // relative against 0.819 absolute, docs/benchmarks.md "Fewer views,
  // relative vote saturation".) Not the views actually voting: at a
  // sequence's ends, where fewer views see a point, that would *raise* the
  // confidence of what little support there is.
  bool confidence_from_votes = true;
  double votes_saturation_per_view = 0.25;
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
  // `window_views`: FullWindowViews of the maps the grid holds (for the vote saturation).
  DepthMap Filter(const DepthMap& map, const PinholeView& view, double window_views) const;

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

// The views a full vote window (max_view_angle_deg on both sides) holds at the
// spacing of `voters` (viewing directions, in sequence order; the filtered
// view among them): 1 + 2 max_view_angle_deg / the median angle between
// consecutive voters, or the voters' own count where that is more (several
// passes over the same path). A robust spacing: a closed loop's seam is one
// large step.
double FullWindowViews(const std::vector<Eigen::Vector3d>& voters, double max_view_angle_deg);

// Filters one view given the sparse maps of its neighbours within 15° (and itself), in sequence order.
// For sequences, prefer SlidingDepthFilter.
DepthMap FilterDepth(const DepthMap& map, const PinholeView& view, const std::vector<const DepthMap*>& voters,
                     const std::vector<const PinholeView*>& voter_views, const BoundingBox& volume,
                     const DepthFilterOptions& options);

}  // namespace lfrecon
