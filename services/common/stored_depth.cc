#include "common/stored_depth.h"

#include <algorithm>

#include "util/error.h"

namespace lfrecon::svc {

std::vector<int> ConsistencyNeighbours(const JobGeometry& geo, int v, bool* complete) {
  if (complete) *complete = true;
  const GeometricConsistencyOptions& gc = geo.options.geometric_consistency;
  if (!geo.options.densify || gc.Delay() == 0) return {};
  const ReconstructionPlan& plan = geo.plan;
  // An open stream's plan is final up to `known` positions of its order.
  const int known = plan.FinalOrder(!geo.open, geo.options);
  const int p = v >= 0 && v < static_cast<int>(plan.order_position.size())
                    ? plan.order_position[static_cast<std::size_t>(v)]
                    : -1;
  if (p < 0 || p >= known) {  // not (yet) in the plan's final order: nothing to compare with before it is
    if (complete) *complete = !geo.open;
    return {};
  }
  if (complete && geo.open && p + gc.Delay() >= known) *complete = false;
  std::vector<int> out;
  for (int q : NeighbourPositions(p, known, gc)) out.push_back(plan.order[static_cast<std::size_t>(q)]);
  return out;
}

cv::Mat StoredDepthCache::Depth(const JobGeometry& geo, int v) {
  auto it = maps_.find(v);
  if (it == maps_.end()) {
    cv::Mat depth = store_.ReadMap(id_, pb::MAP_DENSE, v, geo.views[static_cast<std::size_t>(v)]).depth;
    while (!maps_.empty() && maps_.size() >= capacity_) {
      auto oldest = maps_.begin();
      for (auto m = maps_.begin(); m != maps_.end(); ++m)
        if (m->second.first < oldest->second.first) oldest = m;
      maps_.erase(oldest);
    }
    it = maps_.emplace(v, std::make_pair(tick_, std::move(depth))).first;
  }
  it->second.first = ++tick_;
  return it->second.second;  // shares the pixels: eviction does not free them under the caller
}

GeometricConsistencyStats CheckStoredDenseMap(const JobGeometry& geo, int v, const cv::Mat& own,
                                              StoredDepthCache* cache, DepthMap* dense, int* unreadable) {
  if (!geo.options.densify || geo.options.geometric_consistency.Delay() == 0) return {};
  const std::vector<int> nbs = ConsistencyNeighbours(geo, v, nullptr);
  std::vector<cv::Mat> depths;
  depths.reserve(nbs.size());
  for (int w : nbs) {
    try {
      depths.push_back(cache->Depth(geo, w));
    } catch (const InputError&) {
      if (unreadable) *unreadable = w;
      throw;
    }
  }
  std::vector<NeighbourDepth> in;
  for (std::size_t k = 0; k < nbs.size(); ++k) in.push_back({&geo.views[static_cast<std::size_t>(nbs[k])], &depths[k]});
  return ApplyGeometricConsistency(geo.views[static_cast<std::size_t>(v)], own, in, geo.volume,
                                   geo.options.geometric_consistency, dense);
}

}  // namespace lfrecon::svc
