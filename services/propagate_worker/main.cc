// lfrecon-propagate: a propagation worker. Each task is one view: voxel-vote
// filtering (§3.2, VoteGrid) of its sparse map with the sparse maps of the
// views within 15°, then edge-aware densification (§4, DepthPropagator) with
// the frames within 5°, all read from the job store. The dense map goes to the
// aggregator, with the mask of its own (filtered) depths for the aggregator's
// geometric consistency check. With the job's no_densify the filtered map goes instead.
#include <algorithm>
#include <iostream>
#include <memory>
#include <set>

#include "common/worker_loop.h"
#include "depth/sliding_vote_grid.h"
#include "fusion/geometric_consistency.h"
#include "propagation/depth_propagator.h"
#include "util/memory.h"

int main(int argc, char** argv) {
  lfrecon::ConfigureHeap();
  using namespace lfrecon;
  using namespace lfrecon::svc;
  WorkerOptions o;
  bool ok = false;
  const int code = ParseWorkerFlags(
      argc, argv, "lfrecon-propagate: filtering (§3.2) and densification (§4) worker of the lfrecon service", &o, &ok);
  if (!ok) return code;
  try {
    InstallStopHandlers();
    return RunWorker(o, pb::STAGE_PROPAGATE, "propagate", [](const pb::Task& task, const std::string& job,
                                                             StoreCache& cache) {
      const JobGeometry& g = cache.Geometry(job);
      const PipelineOptions& po = g.options;
      const int v = static_cast<int>(task.view());
      if (task.frames_size() < 1 || static_cast<int>(task.frames(0)) != v)
        throw std::invalid_argument("propagate task must list its own view first");
      const DepthMap& sparse = cache.SparseMap(job, v);
      DepthMap base = sparse;
      if (po.depth.run_filter) {
        // The vote grid of the views within 15° (§3.2), kept between tasks and
        // slid by adding/removing voters, as StreamingDepth slides it: a
        // worker that gets consecutive views splats ~2 maps per task, not all.
        static std::string grid_job;
        static std::unique_ptr<SlidingVoteGrid> grid;
        if (grid_job != job || !grid) {
          grid = std::make_unique<SlidingVoteGrid>(g.volume, po.depth.filter);
          grid_job = job;
        }
        std::set<int> voters(task.voters().begin(), task.voters().end());
        voters.insert(v);
        for (int j : voters)
          if (j < 0 || j >= static_cast<int>(g.views.size())) throw std::invalid_argument("voter out of range");
        grid->MoveTo(
            voters, [&](int j) { return cache.SparseMap(job, j); },
            [&](int j) -> const PinholeView& { return g.views[j]; });
        base = grid->Filter(sparse, g.views[v]);
      }
      if (!po.densify) return DepthMapToProto(base, v, pb::MAP_FILTERED);
      const ViewImage& ref = cache.Frame(job, v);
      std::vector<const ViewImage*> nbs;
      for (int k = 1; k < task.frames_size(); ++k) nbs.push_back(&cache.Frame(job, static_cast<int>(task.frames(k))));
      const DepthPropagator propagator(po.propagation);
      const DepthMap dense = propagator.Run(ref, nbs, base, g.volume).dense;
      // The depths the aggregator's geometric consistency check spares, as lfrecon run marks them.
      const GeometricConsistencyOptions& gc = po.geometric_consistency;
      return DepthMapToProto(dense, v, pb::MAP_DENSE, gc.enabled ? OwnDepthMask(dense, base, gc.own_tolerance) : cv::Mat());
    });
  } catch (const std::exception& e) {
    std::cerr << "lfrecon-propagate: error: " << e.what() << "\n";
    return 1;
  }
}
