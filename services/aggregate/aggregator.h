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
// No algorithm here: the stages are the libraries' calls.
#include <chrono>
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
  // One request -> its reply (never throws).
  pb::Envelope Handle(const pb::Envelope& request);

 private:
  struct Job;
  using Clock = std::chrono::steady_clock;
  Job* FindJob(const std::string& id);  // loads from the store on first use; nullptr if unknown
  std::unique_ptr<Job> LoadJob(const std::string& id);
  pb::Envelope HandleTaskRequest(const pb::Envelope& req);
  pb::Envelope HandleTaskResult(Job& job, const pb::TaskResult& result);
  pb::Envelope HandleExport(Job& job, const pb::ExportRequest& req);
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
