#include "worker_loop.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <iostream>
#include <set>
#include <thread>

#include "util/error.h"
#include "util/logging.h"
#include "util/memory.h"
#include "util/progress.h"

namespace lfrecon::svc {

const JobGeometry& StoreCache::Geometry(const std::string& job) {
  auto& g = geometry_[job];
  if (!g) g = std::make_unique<JobGeometry>(LoadJobGeometry(store_, job));
  return *g;
}

void StoreCache::Cover(const std::string& job, int index) {
  Geometry(job);
  JobGeometry& g = *geometry_[job];
  if (g.open && index >= static_cast<int>(g.views.size())) GrowStreamGeometry(store_, &g);
}

StoreCache::Entry& StoreCache::Get(const std::string& job, int kind, int index) {
  const JobGeometry& g = Geometry(job);
  if (index < 0 || index >= static_cast<int>(g.views.size()))
    throw std::invalid_argument("view " + std::to_string(index) + " out of range");
  auto key = std::make_tuple(job, kind, index);
  auto it = entries_.find(key);
  if (it == entries_.end()) {
    Entry e;
    if (kind == 0) {
      e.frame.view = g.views[index];
      // The job plan's hierarchy-grid flag (as StreamingDepth sets it in lfrecon run):
      // a depth task's later levels use grid frames only.
      e.frame.on_grid = g.plan.OnGrid(index);
      e.frame.image = store_.ReadFrame(job, index, g.views[index]);
      PrepareViewImage(&e.frame, g.options.depth.gradient);
      ++frames_read_;
    } else {
      e.map = store_.ReadMap(job, pb::MAP_SPARSE, index, g.views[index]);
    }
    it = entries_.emplace(key, std::move(e)).first;
    max_held_ = std::max(max_held_, static_cast<int>(entries_.size()));
  }
  it->second.last_use = ++tick_;
  return it->second;
}

const ViewImage& StoreCache::Frame(const std::string& job, int index) { return Get(job, 0, index).frame; }
const DepthMap& StoreCache::SparseMap(const std::string& job, int index) { return Get(job, 1, index).map; }

void StoreCache::BeginTask() { task_start_ = tick_ + 1; }

void StoreCache::Trim() {
  while (static_cast<int>(entries_.size()) > capacity_) {
    auto oldest = entries_.end();
    for (auto it = entries_.begin(); it != entries_.end(); ++it)
      if (it->second.last_use < task_start_ && (oldest == entries_.end() || it->second.last_use < oldest->second.last_use))
        oldest = it;
    if (oldest == entries_.end()) break;  // everything left is the current task's
    entries_.erase(oldest);
  }
  if (geometry_.size() > 8) geometry_.clear();
}

int RunWorker(const WorkerOptions& o, pb::Stage stage, const std::string& name, const StageFunction& compute) {
  zmq::context_t context(1);
  JobStore store(o.store);
  StoreCache cache(store, o.cache_entries);
  RequestClient client(context, o.aggregate, o.max_message_bytes, o.security);
  char host[256] = "host";
  ::gethostname(host, sizeof(host) - 1);
  const std::string worker = name + "@" + host + ":" + std::to_string(::getpid());
  spdlog::info("{}: worker {} asking {}", name, worker, o.aggregate);
  int tasks = 0;
  double busy = 0;
  Timer since_contact;
  while (!StopRequested()) {
    pb::Envelope req = NewEnvelope();
    req.mutable_task_request()->set_stage(stage);
    req.mutable_task_request()->set_worker(worker);
    auto reply = client.Request(req, std::chrono::milliseconds(3000));
    if (!reply) {
      if (since_contact.Seconds() > 10) {
        spdlog::warn("{}: no answer from the aggregator {}; still trying", name, o.aggregate);
        since_contact.Restart();
      }
      continue;
    }
    since_contact.Restart();
    if (reply->has_no_task()) {
      std::this_thread::sleep_for(std::chrono::milliseconds(std::max<std::uint32_t>(1, reply->no_task().retry_ms())));
      continue;
    }
    if (!reply->has_task()) {
      spdlog::warn("{}: unexpected reply '{}': {}", name, BodyName(*reply),
                   reply->has_error() ? reply->error().message() : "");
      std::this_thread::sleep_for(std::chrono::milliseconds(500));
      continue;
    }
    const pb::Task& task = reply->task();
    const std::string job = reply->job_id();
    if (o.stall_after_tasks >= 0 && tasks >= o.stall_after_tasks) {
      spdlog::warn("{}: --stall-after-tasks {}: holding view {} of job {} until killed", name, o.stall_after_tasks,
                   task.view(), job);
      while (!StopRequested()) std::this_thread::sleep_for(std::chrono::milliseconds(50));
      break;
    }
    pb::Envelope result = NewEnvelope(job);
    pb::TaskResult* r = result.mutable_task_result();
    r->set_stage(stage);
    r->set_view(task.view());
    r->set_worker(worker);
    Timer t;
    try {
      if (!JobStore::ValidJobId(job)) throw std::invalid_argument("invalid job id '" + job + "'");
      if (tasks < o.fail_tasks) throw std::runtime_error("--fail-tasks " + std::to_string(o.fail_tasks) + ": fault injection");
      // A stream still open: its frames so far (the task's are stored: the aggregator leased it so).
      int last = static_cast<int>(task.view());
      for (std::uint32_t k : task.frames()) last = std::max(last, static_cast<int>(k));
      for (std::uint32_t k : task.voters()) last = std::max(last, static_cast<int>(k));
      cache.Cover(job, last);
      cache.BeginTask();
      *r->mutable_map() = compute(task, job, cache);
      cache.Trim();
    } catch (const std::exception& e) {
      spdlog::error("{}: view {} of job {}: {}", name, task.view(), job, e.what());
      r->set_error(e.what());
    }
    r->set_seconds(t.Seconds());
    busy += t.Seconds();
    ++tasks;
    // The result is worth delivering even if the aggregator is restarting: retry a while.
    bool delivered = false;
    for (int attempt = 0; attempt < 40 && !delivered && !StopRequested(); ++attempt) {
      auto ack = client.Request(result, std::chrono::milliseconds(3000));
      if (!ack) continue;
      delivered = true;
      if (ack->has_error()) spdlog::warn("{}: result of view {} refused: {}", name, task.view(), ack->error().message());
      if (ack->has_error() && ack->error().code() == pb::ERROR_TOO_LARGE && r->error().empty()) {
        // Its map never reached the aggregator: say so (a small message), so the
        // view is retried a bounded number of times instead of leased for ever.
        const std::size_t bytes = result.ByteSizeLong();
        r->clear_map();
        r->set_error("result of " + std::to_string(bytes) + " bytes refused by the aggregator: " +
                     ack->error().message());
        delivered = false;
      }
    }
    spdlog::debug("{}: view {} of job {} in {:.3f} s", name, task.view(), job, t.Seconds());
  }
  spdlog::info("{}: stopped after {} tasks ({:.1f} s busy), {} frames read, at most {} cached, peak RSS {} MiB", name,
               tasks, busy, cache.frames_read(), cache.max_held(), PeakRssBytes() / 1048576);
  return 0;
}

int ParseWorkerFlags(int argc, char** argv, const std::string& description, WorkerOptions* o, bool* ok) {
  CLI::App app{description};
  o->aggregate = EndpointFromEnv("LFRECON_AGGREGATE", kDefaultAggregateEndpoint);
  std::string store;
  double max_mb = kDefaultMaxMessageBytes / 1048576.0;
  int verbosity = 0;
  SecurityFlags security;
  AddClientSecurityFlags(&app, &security, "--aggregate-key", "LFRECON_AGGREGATE_KEY");
  app.add_option("--aggregate", o->aggregate, "The aggregator's endpoint (default: $LFRECON_AGGREGATE or loopback)")
      ->capture_default_str();
  app.add_option("--store", store, "Job store folder")->required();
  app.add_option("--max-message-mb", max_mb, "Largest message accepted or sent, MiB")->capture_default_str();
  app.add_option("--cache", o->cache_entries, "Frames/maps kept between tasks")->capture_default_str();
  app.add_option("--stall-after-tasks", o->stall_after_tasks,
                 "Fault injection (tests): hold the task after this many until killed");
  app.add_option("--fail-tasks", o->fail_tasks, "Fault injection (tests): the first this many tasks report an error");
  app.add_flag("-v,--verbose", verbosity, "More logging");
  *ok = false;
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);
    return code == 0 ? 0 : 2;
  }
  SetupLogging(verbosity);
  try {
    o->security = ResolveClientSecurity(security);
    CheckClientEndpoint(o->aggregate, o->security);
  } catch (const OptionError& e) {
    std::cerr << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "error: " << e.what() << "\n";
    return 1;
  }
  o->store = store;
  o->max_message_bytes = static_cast<std::int64_t>(max_mb * 1048576.0);
  *ok = true;
  return 0;
}

}  // namespace lfrecon::svc
