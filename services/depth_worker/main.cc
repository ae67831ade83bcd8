// lfrecon-depth: a depth worker. Each task is one view: its frame and the
// frames its hierarchy uses (the job plan's depth neighbours among the views
// within 5°, in the estimator's order, read from the job store with the plan's
// on_grid flags), and the sparse depth from gradients (§3.1,
// GradientDepthEstimator) with the job's options. Run N of them; the
// aggregator hands out the views.
#include <iostream>

#include "common/worker_loop.h"
#include "depth/gradient_depth_estimator.h"
#include "util/memory.h"

int main(int argc, char** argv) {
  lfrecon::ConfigureHeap();
  using namespace lfrecon;
  using namespace lfrecon::svc;
  WorkerOptions o;
  bool ok = false;
  const int code = ParseWorkerFlags(argc, argv, "lfrecon-depth: sparse depth worker (§3.1) of the lfrecon service", &o, &ok);
  if (!ok) return code;
  try {
    InstallStopHandlers();
    return RunWorker(o, pb::STAGE_DEPTH, "depth", [](const pb::Task& task, const std::string& job, StoreCache& cache) {
      const JobGeometry& g = cache.Geometry(job);
      if (task.frames_size() < 1 || task.frames(0) != task.view())
        throw std::invalid_argument("depth task must list its own view first");
      const ViewImage& ref = cache.Frame(job, static_cast<int>(task.view()));
      std::vector<const ViewImage*> nbs;
      for (int k = 1; k < task.frames_size(); ++k) nbs.push_back(&cache.Frame(job, static_cast<int>(task.frames(k))));
      const GradientDepthEstimator estimator(g.options.depth.gradient);
      return DepthMapToProto(estimator.Estimate(ref, nbs, g.volume), static_cast<int>(task.view()), pb::MAP_SPARSE);
    });
  } catch (const std::exception& e) {
    std::cerr << "lfrecon-depth: error: " << e.what() << "\n";
    return 1;
  }
}
