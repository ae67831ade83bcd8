// lfrecon-aggregate, view tasks: which task of which job is ready (the job
// plan's neighbours, voters and selected views), its lease and expiry, results
// and failed attempts.
#include "aggregator_job.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>

#include "io/input_text.h"
#include "util/error.h"

namespace lfrecon::svc {
namespace fs = std::filesystem;

// The name is the worker's own claim: its label (in logs, error replies and a
// failed job's message) is sanitised and bounded (PeerText), so a name with
// newlines or 10 kB of text can neither forge log lines nor bloat messages.
constexpr std::size_t kMaxWorkerLabelChars = 64;

Aggregator::WorkerId Aggregator::Worker(const std::string& peer_key, const std::string& name) {
  const std::string label = "'" + PeerText(name, kMaxWorkerLabelChars) + "'";
  if (peer_key.empty()) return {name, label};
  return {"key:" + peer_key, label + " (key " + KeyFingerprint(peer_key) + ")"};
}

void Aggregator::ExpireLeases(Job& job) {
  const auto now = Clock::now();
  std::vector<std::pair<std::pair<int, int>, WorkerId>> expired;
  for (auto it = job.leases.begin(); it != job.leases.end();) {
    if (it->second.deadline < now) {
      expired.emplace_back(it->first, it->second.worker);
      it = job.leases.erase(it);
    } else {
      ++it;
    }
  }
  for (const auto& [key, worker] : expired) {
    ++job.leases_expired;
    if (FailTask(job, key.first, key.second, worker.id,
                 "not returned by " + worker.label + " within its lease of " + std::to_string(options_.lease_ms) +
                     " ms"))
      return;
  }
}

bool Aggregator::FailTask(Job& job, int stage, int view, const std::string& worker, const std::string& why) {
  Job::Tries& t = job.tries[{stage, view}];
  ++t.failures;
  ++job.tasks_failed;
  t.failed_on.insert(worker);
  const std::string task = std::string(stage == pb::STAGE_DEPTH ? "depth" : "propagate") + " of view " +
                           std::to_string(view);
  if (t.failures >= options_.max_task_attempts) {
    EndJob(job, pb::STATE_FAILED, task + " failed " + std::to_string(t.failures) + " times; the last: " + why);
    return true;
  }
  spdlog::warn("aggregate: job {}: {} failed (attempt {} of {}): {}; re-issued", job.id, task, t.failures,
               options_.max_task_attempts, why);
  return false;
}

bool Aggregator::OtherWorkerAlive(int stage, const std::string& worker) const {
  const auto recent = Clock::now() - std::chrono::milliseconds(std::min(options_.lease_ms, 10000));
  for (const auto& [name, seen] : seen_workers_[stage])
    if (name != worker && seen > recent) return true;
  return false;
}

pb::Envelope Aggregator::HandleTaskRequest(const pb::Envelope& req, const WorkerId& worker) {
  const pb::TaskRequest& tr = req.task_request();
  const int stage = tr.stage();
  if (stage != pb::STAGE_DEPTH && stage != pb::STAGE_PROPAGATE)
    return ErrorEnvelope(pb::ERROR_BAD_REQUEST, "unknown stage " + std::to_string(stage));
  auto& seen = seen_workers_[stage];
  if (seen.size() > 1000) {  // forget workers gone for a minute
    const auto old = Clock::now() - std::chrono::seconds(60);
    for (auto it = seen.begin(); it != seen.end();) it = it->second < old ? seen.erase(it) : std::next(it);
  }
  // A worker's first request is logged: operators see who serves, and a test
  // can wait until every worker it started has been heard from.
  if (seen.insert_or_assign(worker.id, Clock::now()).second)
    spdlog::info("aggregate: {} worker {} asks for tasks", stage == pb::STAGE_DEPTH ? "depth" : "propagate",
                 worker.label);
  const bool others = OtherWorkerAlive(stage, worker.id);
  for (auto& [id, jp] : jobs_) {
    Job& job = *jp;
    if (!job.active) continue;
    ExpireLeases(job);
    if (!job.active) continue;  // a task failed too often
    for (int v = 0; v < job.n; ++v) {
      // Of an open stream only the settled views: their plan entries are the whole stream's.
      if (v >= (stage == pb::STAGE_DEPTH ? job.settled_depth : job.settled)) break;
      if (job.leases.count({stage, v})) continue;
      if (others) {  // a task that failed on this worker goes to another one
        const auto t = job.tries.find({stage, v});
        if (t != job.tries.end() && t->second.failed_on.count(worker.id)) continue;
      }
      pb::Envelope out = NewEnvelope(id);
      pb::Task* task = out.mutable_task();
      // What each task reads is the plan's: a depth task the frames its
      // hierarchy uses (in the estimator's order), a propagate task the
      // filter's voters and the photoconsistency frames.
      const ReconstructionPlan& plan = job.geo.plan;
      if (stage == pb::STAGE_DEPTH) {
        if (!plan.NeedsSparse(v) || job.sparse_ok[v] || !job.FramesOk(v, plan.DepthNeighbours(v))) continue;
        task->add_frames(v);
        for (int j : plan.DepthNeighbours(v)) task->add_frames(j);
      } else {
        if (!plan.Selected(v) || job.dense_ok[v] || !job.sparse_ok[v]) continue;
        const std::vector<int>& voters = plan.Voters(v);
        bool ready = true;
        for (int j : voters) ready = ready && job.sparse_ok[j];
        if (!ready) continue;
        task->add_frames(v);
        if (job.geo.options.densify) {
          if (!job.FramesOk(v, plan.PhotoNeighbours(v))) continue;
          for (int j : plan.PhotoNeighbours(v)) task->add_frames(j);
        }
        for (int j : voters) task->add_voters(j);
      }
      task->set_stage(static_cast<pb::Stage>(stage));
      task->set_view(v);
      task->set_lease_ms(options_.lease_ms);
      job.leases[{stage, v}] = {Clock::now() + std::chrono::milliseconds(options_.lease_ms), worker};
      job.leased_to[{stage, v}].insert(worker.id);
      spdlog::debug("aggregate: job {}: {} of view {} -> {}", id, stage == pb::STAGE_DEPTH ? "depth" : "propagate", v,
                    worker.label);
      return out;
    }
  }
  pb::Envelope out = NewEnvelope();
  out.mutable_no_task()->set_retry_ms(options_.retry_ms);
  return out;
}

pb::Envelope Aggregator::HandleTaskResult(Job& job, const pb::TaskResult& r, const WorkerId& worker) {
  const int v = static_cast<int>(r.view());
  if (!job.active) {  // ended meanwhile (cancelled, failed, done): nothing to do
    pb::Envelope ack = NewEnvelope(job.id);
    ack.mutable_ack();
    return ack;
  }
  if (v < 0 || v >= job.n) return ErrorEnvelope(pb::ERROR_BAD_REQUEST, "view " + std::to_string(v) + " out of range", job.id);
  if (r.stage() != pb::STAGE_DEPTH && r.stage() != pb::STAGE_PROPAGATE)
    return ErrorEnvelope(pb::ERROR_BAD_REQUEST, "unknown stage", job.id);
  // A result must answer a lease: this view, this stage, given to this worker
  // (now or before it expired; a restarted aggregator has given nothing yet).
  // With CURVE the worker is its key, not the name it gives: another worker's
  // key cannot answer (or fail) a lease, whatever name it claims.
  const std::pair<int, int> key{static_cast<int>(r.stage()), v};
  const std::string task = std::string(r.stage() == pb::STAGE_DEPTH ? "depth" : "propagate") + " of view " +
                           std::to_string(v);
  const auto given = job.leased_to.find(key);
  if (given == job.leased_to.end() || !given->second.count(worker.id)) {
    // Leased to someone else: not this peer's to answer. Never leased: a bad request.
    const bool others = given != job.leased_to.end() && !given->second.empty();
    return ErrorEnvelope(others ? pb::ERROR_FORBIDDEN : pb::ERROR_BAD_REQUEST,
                         task + " was not leased to " + worker.label, job.id);
  }
  const bool done = r.stage() == pb::STAGE_DEPTH ? job.sparse_ok[v] : job.dense_ok[v];
  const auto lease = job.leases.find(key);
  if (!r.error().empty()) {
    if (lease != job.leases.end() && lease->second.worker.id == worker.id) job.leases.erase(lease);
    // The worker's error text is as untrusted as its name.
    if (!done) FailTask(job, key.first, v, worker.id, worker.label + ": " + PeerText(r.error()));
    pb::Envelope ack = NewEnvelope(job.id);
    ack.mutable_ack();
    return ack;
  }
  const std::string what = "task result of view " + std::to_string(v) + " from " + worker.label;
  if (r.map().view() != r.view())
    return ErrorEnvelope(pb::ERROR_BAD_REQUEST, what + ": its depth map says view " + std::to_string(r.map().view()),
                         job.id);
  DepthMap map;
  try {
    map = DepthMapFromProto(r.map(), job.geo.views[v].width, job.geo.views[v].height, what);
  } catch (const InputError& e) {
    return ErrorEnvelope(pb::ERROR_BAD_REQUEST, e.what(), job.id);
  }
  const bool sparse_stage = r.stage() == pb::STAGE_DEPTH;
  if (sparse_stage ? r.map().kind() != pb::MAP_SPARSE
                   : r.map().kind() != pb::MAP_DENSE && r.map().kind() != pb::MAP_FILTERED)
    return ErrorEnvelope(pb::ERROR_BAD_REQUEST, what + (sparse_stage ? ": not a sparse map" : ": not a dense map"),
                         job.id);
  if (lease != job.leases.end()) job.leases.erase(lease);
  if (!done) {
    pb::DepthMap stored = r.map();
    stored.set_view(v);
    if (!sparse_stage) stored.set_kind(pb::MAP_DENSE);  // the map that is fused, whatever the stage made
    try {
      // In the store (the checkpoint) before the ack: a restart fuses it if the fusion thread did not.
      store_.WriteMap(job.id, stored);
    } catch (const std::exception& e) {  // a full disk: the job fails, nothing is re-issued for ever
      EndJob(job, pb::STATE_FAILED, "job store: " + std::string(e.what()));
      return ErrorEnvelope(pb::ERROR_INTERNAL, "job " + job.id + " failed: " + job.message, job.id);
    }
    if (sparse_stage) {
      job.sparse_ok[v] = 1;
      ++job.sparse_done;
    } else {
      Enqueue(job, v, true);
    }
  }
  pb::Envelope ack = NewEnvelope(job.id);
  ack.mutable_ack();
  return ack;
}

}  // namespace lfrecon::svc
