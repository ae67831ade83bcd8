#pragma once
// A job's stored dense maps as the service fuses them: multi-view geometric
// consistency (PipelineOptions::geometric_consistency) applied as lfrecon run
// applies it. View v's stored (unchecked) dense map is checked against the
// stored unchecked dense maps of the plan's views at v's position ± the
// offsets in the plan's order (ConsistencyNeighbours), sparing the depths its propagation worker
// marked as its own (pb::DepthMap.own). Used by the aggregator's fusion and
// refined export, and by tests that compare the service with lfrecon run.
#include <cstdint>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "common/job_store.h"
#include "fusion/geometric_consistency.h"

namespace lfrecon::svc {

// The views whose maps view v's check reads: the plan's views at v's position
// ± the offsets in ReconstructionPlan::order; none when the check is off (or
// without densification). `complete` (may be null): false while an open
// stream's plan is not final up to v's last neighbour (v must wait).
std::vector<int> ConsistencyNeighbours(const JobGeometry& geo, int v, bool* complete);
// The depth channels of stored dense maps, the most recently used kept: the
// neighbours of views fused one after another are mostly the same maps.
class StoredDepthCache {
 public:
  StoredDepthCache(const JobStore& store, std::string id, std::size_t capacity)
      : store_(store), id_(std::move(id)), capacity_(capacity) {}
  // Enough for a job's fusion in the plan's order: consecutive views' neighbours
  // lie within Delay() positions before and after them (2·Delay() + 1 maps),
  // and one more.
  static std::size_t CapacityFor(const GeometricConsistencyOptions& options) {
    return 2 * static_cast<std::size_t>(options.Delay()) + 2;
  }
  // Throws InputError naming the map's file when it is missing or unreadable.
  cv::Mat Depth(const JobGeometry& geo, int v);
  void Forget(int v) { maps_.erase(v); }

 private:
  const JobStore& store_;
  std::string id_;
  std::size_t capacity_;
  std::uint64_t tick_ = 0;
  std::map<int, std::pair<std::uint64_t, cv::Mat>> maps_;  // view -> (last use, depth)
};
// Applies the check to `dense`, view v's stored map with its own-depth mask
// `own` (empty: none spared). Throws InputError when a neighbour's map is
// unreadable, with that view in *unreadable (may be null).
GeometricConsistencyStats CheckStoredDenseMap(const JobGeometry& geo, int v, const cv::Mat& own,
                                              StoredDepthCache* cache, DepthMap* dense, int* unreadable);

}  // namespace lfrecon::svc
