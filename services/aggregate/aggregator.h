#pragma once
// lfrecon-aggregate: the job's coordinator and volume aggregator.
//  * Leases view tasks to the depth and propagate workers as soon as their
//    inputs are in the job store (frames within 5° for depth; sparse maps
//    within 15° and frames within 5° for propagate). A lease not returned in
//    time (worker killed, stuck) expires and the view is handed out again;
//    duplicate results are ignored.
//  * Acknowledges a dense map once it is written to the store, and fuses it
//    into the job's ProbabilisticFusion (OpenVDB) on the job's own fusion
//    thread, in the order the maps were received (§5 is order independent),
//    appending its id to fused.log after it is integrated: the store's dense
//    maps and fused.log are the checkpoint. A restarted aggregator replays
//    them (fused.log order, then the stored maps not logged yet in view
//    order) on that thread and the job continues; it answers meanwhile.
//    Status reports the maps received (dense_done) and fused (views_fused).
//    When the last view is fused, that thread writes mesh_raw.ply, mesh.ply
//    (and grid.vdb); the job is DONE once they are written. Cancel, a failure
//    and SIGTERM stop the thread after the view it is integrating.
//  * Answers status, export (mesh of what is fused so far, also mid-stream:
//    extracted under the grid's lock, so never of half a view) and cancel at
//    any time: nothing on the serving thread waits for fusion. A plain export
//    is computed off the serving thread (one at a time, others queue).
//  * Export with refine (voxel carving + screened Poisson, libs/refine, as
//    `lfrecon run` makes mesh.ply) runs off the serving thread, one at a time
//    (others wait in a queue), so the daemon keeps leasing, fusing and
//    answering meanwhile. It refines a private grid rebuilt from the
//    checkpoint (the fused views' dense maps in view order: the live grid up
//    to float rounding): for a job still running, of the views fused when the request
//    came; for a finished job (whose grid was released), of all of them. The
//    carving and colour frames are read from the store for that export only.
//    A finished job's refined mesh is kept as mesh_refined.ply and served
//    from there afterwards.
//  * What is computed, from which frames and maps, and when a job is done
//    follow the job's ReconstructionPlan (JobGeometry::plan), the plan
//    `lfrecon run` computes for the same cameras and options.
//  * A client-pushed stream that gives V is a job from its opening: its plan
//    is computed again on the frames stored so far, and the views it settles
//    (their entries no later frame changes) are leased and fused while the
//    stream is open, the rest after its end (stream_plan.cc).
// No algorithm here: the stages are the libraries' calls. One job per file:
// aggregator.cc (dispatch), leases.cc (view tasks), job_fusion.cc (a job's
// fusion and checkpoint), export.cc (exports), stream_plan.cc (an open
// stream's growing plan); aggregator_job.h (a job's state).
#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "common/job_store.h"
#include "common/messaging.h"
#include "fusion/probabilistic_fusion.h"

namespace lfrecon::svc {

struct AggregatorOptions {
  std::string endpoint = kDefaultAggregateEndpoint;
  std::filesystem::path store;
  std::int64_t max_message_bytes = kDefaultMaxMessageBytes;
  int lease_ms = 60000;  // a view task not returned within this is re-issued
  int retry_ms = 20;     // a worker with nothing to do asks again after this
  // A view task that failed this many times (error results, expired leases)
  // fails its job with the last reason; before that it is re-issued, to
  // another worker of the stage when one asked for work recently.
  int max_task_attempts = 3;
  // A job still ingesting that has heard nothing from ingest for this long
  // fails (ingest died and did not come back to resume it).
  double ingest_timeout_s = 600;
  // Exports waiting (plus the one running) per lane, plain and refined; more are refused (ERROR_BUSY).
  int max_queued_exports = 8;
  // Fault injection for the integration tests: each view's integration holds
  // the grid this much longer (slow fusion, as a big grid has). 0: off.
  int fusion_delay_ms = 0;
  ServerSecurity security;  // CURVE key and allow-list, or plain (common/auth.h)
};

class Aggregator {
 public:
  explicit Aggregator(const AggregatorOptions& options);
  ~Aggregator();
  // Serves until StopRequested().
  void Serve();
  // One request -> its reply (never throws). An export is computed here, in
  // the caller's thread; Serve() computes it off the serving thread. Fusion
  // runs on the jobs' threads either way.
  pb::Envelope Handle(const pb::Envelope& request);

 private:
  struct Job;
  using Clock = std::chrono::steady_clock;
  // Work whose reply is computed off the serving thread; it reads the job
  // store, what it captured and (plain export) the job's grid under its lock,
  // never the serving thread's state; it never throws.
  using Work = std::function<pb::Envelope()>;
  enum class Lane { kExport, kRefine };  // each lane runs one at a time, in arrival order
  struct Deferred {
    Work work;
    Lane lane = Lane::kExport;
  };
  // `deferred` null: everything is answered here; else a request whose work
  // can run elsewhere sets deferred->work and the returned envelope is meaningless.
  // `peer_key`: the sender's CURVE public key (RouterServer::Incoming::peer_key),
  // empty on a socket without CURVE.
  pb::Envelope Handle(const pb::Envelope& request, Deferred* deferred, const std::string& peer_key = "");
  Job* FindJob(const std::string& id);  // loads from the store on first use; nullptr if unknown
  std::unique_ptr<Job> LoadJob(const std::string& id);
  // A worker as leases know it: `id` is who it is (with CURVE its public key,
  // authenticated by the handshake; without, the name it gives, which any
  // peer can claim), `label` how logs and messages name it.
  struct WorkerId {
    std::string id, label;
  };
  static WorkerId Worker(const std::string& peer_key, const std::string& name);
  pb::Envelope HandleTaskRequest(const pb::Envelope& req, const WorkerId& worker);
  pb::Envelope HandleTaskResult(Job& job, const pb::TaskResult& result, const WorkerId& worker);
  pb::Envelope HandleExport(Job& job, const pb::ExportRequest& req, Deferred* deferred);
  Work RefinedExport(const Job& job) const;
  Work PlainExport(Job& job) const;
  // Fusion thread of a job: integrates the queued views until stopped.
  void FusionLoop(Job* job) const;
  void Enqueue(Job& job, int view, bool log) const;
  static void StopFusion(Job& job, bool join);
  // Serving thread: a job whose fusion thread finished (outputs written) or failed ends here.
  void Reap(Job& job);
  // Serving thread, an open stream's job (stream_plan.cc): the frames stored
  // since, its end (the manifest's plan replaces the prefix's) or its failure at ingest.
  void GrowStream(Job& job);
  void EndJob(Job& job, pb::JobState state, const std::string& message);
  pb::JobStatus Status(const Job& job) const;
  void ExpireLeases(Job& job);
  // Counts a failed attempt at a view task; true if the job failed of it.
  bool FailTask(Job& job, int stage, int view, const std::string& worker, const std::string& why);
  // Another worker of `stage` than `worker` asked for work within the last few seconds.
  bool OtherWorkerAlive(int stage, const std::string& worker) const;
  // A job that cannot be loaded (bad manifest or options) is FAILED with the reason, not an error for ever.
  std::unique_ptr<Job> LoadOrFail(const std::string& id);

  AggregatorOptions options_;
  JobStore store_;
  std::unique_ptr<FileLock> lock_;  // flock on the store folder: one aggregator per store
  std::map<std::string, Clock::time_point> seen_workers_[3];  // per stage: worker id -> its last task request
  std::map<std::string, std::unique_ptr<Job>> jobs_;
};

}  // namespace lfrecon::svc
