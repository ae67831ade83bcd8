#pragma once
// The loop every stage worker runs: ask the aggregator for a view task
// (TaskRequest -> Task | NoTask), compute it with the stage's library call,
// send the map back (TaskResult -> Ack). Frames and maps are read from the job
// store through a small cache that keeps what the current task needs plus the
// most recently used entries up to a capacity, so a worker that gets
// neighbouring views re-reads little, and its memory is bounded by its window.
#include <functional>
#include <list>
#include <map>
#include <memory>
#include <string>

#include "common/job_store.h"
#include "common/messaging.h"
#include "depth/gradient_depth_estimator.h"

namespace lfrecon::svc {

struct WorkerOptions {
  std::string aggregate = kDefaultAggregateEndpoint;
  std::filesystem::path store;
  std::int64_t max_message_bytes = kDefaultMaxMessageBytes;
  int cache_entries = 64;  // frames (and, for propagate, sparse maps) kept between tasks
  // Fault injection for the integration tests: after this many tasks, take the
  // next one and never return it (the process hangs until killed). < 0: off.
  int stall_after_tasks = -1;
  // Fault injection for the integration tests: the first this many tasks report an error.
  int fail_tasks = 0;
  ClientSecurity security;  // CURVE key (role worker) and the aggregator's public key, or plain
};

// Per-process cache of prepared frames and sparse maps, keyed by (job, index).
class StoreCache {
 public:
  StoreCache(const JobStore& store, int capacity) : store_(store), capacity_(capacity) {}
  const JobGeometry& Geometry(const std::string& job);
  // An open stream's geometry (JobGeometry::open) grown from the store until it
  // holds view `index`. Called before a task, never during one, so what a task
  // holds of the geometry stays valid while it runs.
  void Cover(const std::string& job, int index);
  // The frame of view `index` with PrepareViewImage applied and its on_grid flag
  // from the job's plan (as the depth stage of `lfrecon run` holds it).
  const ViewImage& Frame(const std::string& job, int index);
  const DepthMap& SparseMap(const std::string& job, int index);
  // Drops least recently used entries beyond the capacity, never those used since BeginTask().
  void BeginTask();
  void Trim();
  int frames_read() const { return frames_read_; }
  int max_held() const { return max_held_; }

 private:
  struct Entry {
    ViewImage frame;
    DepthMap map;
    long long last_use = 0;
  };
  Entry& Get(const std::string& job, int kind, int index);
  const JobStore& store_;
  int capacity_;
  long long tick_ = 0, task_start_ = 0;
  int frames_read_ = 0, max_held_ = 0;
  std::map<std::string, std::unique_ptr<JobGeometry>> geometry_;
  std::map<std::tuple<std::string, int, int>, Entry> entries_;
};

// Computes one task's map; throws on failure (the message goes back as the task's error).
using StageFunction = std::function<pb::DepthMap(const pb::Task& task, const std::string& job, StoreCache& cache)>;

// Runs until StopRequested(). `name`: for logs ("depth", "propagate").
int RunWorker(const WorkerOptions& options, pb::Stage stage, const std::string& name, const StageFunction& compute);

// Parses the flags every worker shares; returns false (after printing) on a usage error.
int ParseWorkerFlags(int argc, char** argv, const std::string& description, WorkerOptions* options, bool* ok);

}  // namespace lfrecon::svc
