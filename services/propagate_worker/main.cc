// lfrecon-propagate: a propagation worker. Each task is one view: voxel-vote
// filtering (§3.2, FilterDepth) of its sparse map with the sparse maps of the
// views within 15°, then edge-aware densification (§4, DepthPropagator) with
// the frames within 5°, all read from the job store. The dense map goes to the
// aggregator. With the job's no_densify the filtered map goes instead.
#include <algorithm>
#include <iostream>

#include "common/worker_loop.h"
#include "depth/depth_filter.h"
#include "propagation/depth_propagator.h"

int main(int argc, char** argv) {
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
        std::vector<int> ids(task.voters().begin(), task.voters().end());
        ids.push_back(v);
        std::sort(ids.begin(), ids.end());
        ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
        std::vector<const DepthMap*> maps;
        std::vector<const PinholeView*> views;
        for (int j : ids) {
          maps.push_back(&cache.SparseMap(job, j));
          views.push_back(&g.views.at(j));
        }
        base = FilterDepth(sparse, g.views[v], maps, views, g.volume, po.depth.filter);
      }
      if (!po.densify) return DepthMapToProto(base, v, pb::MAP_FILTERED);
      const ViewImage& ref = cache.Frame(job, v);
      std::vector<const ViewImage*> nbs;
      for (int k = 1; k < task.frames_size(); ++k) nbs.push_back(&cache.Frame(job, static_cast<int>(task.frames(k))));
      const DepthPropagator propagator(po.propagation);
      return DepthMapToProto(propagator.Run(ref, nbs, base, g.volume).dense, v, pb::MAP_DENSE);
    });
  } catch (const std::exception& e) {
    std::cerr << "lfrecon-propagate: error: " << e.what() << "\n";
    return 1;
  }
}
