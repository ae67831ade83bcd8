#pragma once
// lfrecon-aggregate: the job's coordinator and volume aggregator.
//  * Leases view tasks to the depth and propagate workers as soon as their
//    inputs are in the job store (frames within 5° for depth; sparse maps
//    within 15° and frames within 5° for propagate). A lease not returned in
//    time (worker killed, stuck) expires and the view is handed out again;
//    duplicate results are ignored.
//  * Fuses each dense map into the job's ProbabilisticFusion (OpenVDB) as it
//    arrives, in any order (§5 is order independent), after spooling it to the
//    store and before appending its id to fused.log: the store's dense maps
//    and fused.log are the checkpoint. A restarted aggregator replays them in
//    fused.log order (the same sums in the same order: the same grid) and the
//    job continues.
//  * Answers status, export (mesh of what is fused so far, also mid-stream)
//    and cancel at any time.
//  * Export with refine (voxel carving + screened Poisson, libs/refine, as
//    `lfrecon run` makes mesh.ply) runs off the serving thread, one at a time
//    (others wait in a queue), so the daemon keeps leasing, fusing and
//    answering meanwhile. It refines a private grid rebuilt from the
//    checkpoint (the dense maps in fused.log order, the same grid as the
//    live one): for a job still running, of the views fused when the request
//    came; for a finished job (whose grid was released), of all of them. The
//    carving and colour frames are read from the store for that export only.
//    A finished job's refined mesh is kept as mesh_refined.ply and served
//    from there afterwards.
// No algorithm here: the stages are the libraries' calls.
#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <string>

#include "common/job_store.h"
#include "common/messaging.h"
#include "fusion/probabilistic_fusion.h"
#include "geometry/view_graph.h"

namespace lfrecon::svc {

struct AggregatorOptions {
  std::string endpoint = kDefaultAggregateEndpoint;
  std::filesystem::path store;
  std::int64_t max_message_bytes = kDefaultMaxMessageBytes;
  int lease_ms = 60000;  // a view task not returned within this is re-issued
  int retry_ms = 20;     // a worker with nothing to do asks again after this
};

class Aggregator {
 public:
  explicit Aggregator(const AggregatorOptions& options);
  ~Aggregator();
  // Serves until StopRequested().
  void Serve();
  // One request -> its reply (never throws). A refine export is computed here,
  // in the caller's thread; Serve() computes it off the serving thread.
  pb::Envelope Handle(const pb::Envelope& request);

 private:
  struct Job;
  using Clock = std::chrono::steady_clock;
  // Work whose reply is computed off the serving thread; it only reads the job
  // store and what it captured (never the Aggregator), and never throws.
  using Deferred = std::function<pb::Envelope()>;
  // `deferred` null: everything is answered here; else a request whose work
  // can run elsewhere sets *deferred and the returned envelope is meaningless.
  pb::Envelope Handle(const pb::Envelope& request, Deferred* deferred);
  Job* FindJob(const std::string& id);  // loads from the store on first use; nullptr if unknown
  std::unique_ptr<Job> LoadJob(const std::string& id);
  pb::Envelope HandleTaskRequest(const pb::Envelope& req);
  pb::Envelope HandleTaskResult(Job& job, const pb::TaskResult& result);
  pb::Envelope HandleExport(Job& job, const pb::ExportRequest& req, Deferred* deferred);
  Deferred RefinedExport(const Job& job) const;
  void Integrate(Job& job, int view, const DepthMap& map, bool log);
  void MaybeFinish(Job& job);
  void EndJob(Job& job, pb::JobState state, const std::string& message);
  pb::JobStatus Status(const Job& job) const;
  TriangleMesh CurrentMesh(Job& job, bool colour);
  void ExpireLeases(Job& job);

  AggregatorOptions options_;
  JobStore store_;
  std::map<std::string, std::unique_ptr<Job>> jobs_;
};

}  // namespace lfrecon::svc
