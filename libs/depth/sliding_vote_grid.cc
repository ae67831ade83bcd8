#include "depth/sliding_vote_grid.h"

namespace lfrecon {

void SlidingVoteGrid::MoveTo(const std::set<int>& voters, const std::function<DepthMap(int)>& map,
                             const std::function<const PinholeView&(int)>& view) {
  for (auto it = in_grid_.begin(); it != in_grid_.end();) {
    if (!voters.count(*it)) {
      grid_.Splat(map(*it), view(*it), -1.0f);
      directions_.erase(*it);
      it = in_grid_.erase(it);
    } else {
      ++it;
    }
  }
  for (int v : voters)
    if (!in_grid_.count(v)) {
      grid_.Splat(map(v), view(v), 1.0f);
      in_grid_.insert(v);
      directions_[v] = view(v).ViewingDirection();
    }
}

DepthMap SlidingVoteGrid::Filter(const DepthMap& own, const PinholeView& camera) const {
  std::vector<Eigen::Vector3d> dirs;  // in sequence order (the set's)
  for (int v : in_grid_) dirs.push_back(directions_.at(v));
  return grid_.Filter(own, camera, FullWindowViews(dirs, options_.max_view_angle_deg));
}

}  // namespace lfrecon
