#pragma once
// The §3.2 vote grid of a sequence, slid from view to view: it holds the votes
// of one set of sparse maps (a view's filter voters and itself) and moves to
// the next view's set by removing the maps that left it and adding those that
// joined, so consecutive views splat ~2 maps each instead of every voter.
// StreamingDepth (lfrecon run) and the propagate worker (the service) both
// filter through it. Removal subtracts what was added, so the grid equals a
// fresh one up to float rounding that depends on the order of the moves.
#include <functional>
#include <map>
#include <set>

#include "depth/depth_filter.h"

namespace lfrecon {

class SlidingVoteGrid {
 public:
  SlidingVoteGrid(const BoundingBox& volume, const DepthFilterOptions& options)
      : grid_(volume, options), options_(options) {}

  // The grid then holds exactly the votes of `voters`: maps no longer listed
  // are removed (in increasing index), new ones added (likewise). `map(j)` is
  // view j's sparse map, `view(j)` its camera.
  void MoveTo(const std::set<int>& voters, const std::function<DepthMap(int)>& map,
              const std::function<const PinholeView&(int)>& view);
  // Filters `own` (seen from `camera`) with the votes held.
  DepthMap Filter(const DepthMap& own, const PinholeView& camera) const;
  // The views whose votes the grid holds.
  const std::set<int>& voters() const { return in_grid_; }
  bool Holds(int view) const { return in_grid_.count(view) > 0; }

 private:
  VoteGrid grid_;
  DepthFilterOptions options_;
  std::set<int> in_grid_;
  std::map<int, Eigen::Vector3d> directions_;  // of the views in the grid
};

}  // namespace lfrecon
