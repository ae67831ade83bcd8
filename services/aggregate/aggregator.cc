// lfrecon-aggregate, dispatch: the store lock and the jobs it resumes, each
// request to its handler (leases.cc, job_fusion.cc, export.cc), the serving
// loop with the exports' lanes.
#include "aggregator_job.h"

#include <spdlog/spdlog.h>

#include <chrono>
#include <deque>
#include <future>

#include "util/error.h"

namespace lfrecon::svc {
namespace fs = std::filesystem;

Aggregator::Aggregator(const AggregatorOptions& options) : options_(options), store_(options.store) {
  // One aggregator per store: a second one would lease and fuse every view again.
  try {
    lock_ = std::make_unique<FileLock>(store_.root());  // the folder itself: no file in the store
  } catch (const std::runtime_error& e) {
    throw std::runtime_error("another lfrecon-aggregate serves the job store " + store_.root().string() + " (" +
                             e.what() + ")");
  }
  // Resume every job the store holds that has not ended.
  for (const auto& e : fs::directory_iterator(store_.root())) {
    const std::string id = e.path().filename().string();
    if ((!store_.Exists(id) && !GrowingStream(store_, id)) || store_.ReadText(id, "status.pb")) continue;
    jobs_[id] = LoadOrFail(id);
  }
}

Aggregator::~Aggregator() {
  for (auto& [id, job] : jobs_) StopFusion(*job, false);  // all stop together
  jobs_.clear();                                           // joins them
}

Aggregator::Job* Aggregator::FindJob(const std::string& id) {
  const auto it = jobs_.find(id);
  if (it != jobs_.end()) {
    GrowStream(*it->second);
    Reap(*it->second);
    return it->second.get();
  }
  // A job: its manifest, or an open stream that gives V (its plan grows with its frames, stream_plan.cc).
  if (!store_.Exists(id) && !GrowingStream(store_, id)) return nullptr;
  auto job = LoadOrFail(id);
  Job* p = job.get();
  jobs_[id] = std::move(job);
  return p;
}

pb::Envelope Aggregator::Handle(const pb::Envelope& req) { return Handle(req, nullptr); }

pb::Envelope Aggregator::Handle(const pb::Envelope& req, Deferred* deferred, const std::string& peer_key) {
  try {
    switch (req.body_case()) {
      case pb::Envelope::kPing: {
        pb::Envelope out = NewEnvelope();
        out.mutable_pong()->set_daemon("lfrecon-aggregate");
        return out;
      }
      case pb::Envelope::kTaskRequest:
        return HandleTaskRequest(req, Worker(peer_key, req.task_request().worker()));
      default:
        break;
    }
    // Everything else names a job.
    if (!JobStore::ValidJobId(req.job_id()))
      return ErrorEnvelope(pb::ERROR_UNKNOWN_JOB, "invalid job id '" + req.job_id() + "'", req.job_id());
    Job* job = FindJob(req.job_id());
    if (!job && req.has_status() && fs::exists(store_.JobDir(req.job_id()) / "stream.pb")) {
      // A client-pushed stream without V still open at ingest (its manifest comes at its end),
      // or one that failed there.
      pb::Envelope out = NewEnvelope(req.job_id());
      pb::JobStatus* s = out.mutable_job_status();
      if (auto st = store_.ReadText(req.job_id(), "status.pb")) {
        if (!s->ParseFromString(*st)) return ErrorEnvelope(pb::ERROR_INTERNAL, "corrupt status.pb", req.job_id());
        return out;
      }
      s->set_state(pb::STATE_INGESTING);
      std::error_code ec;
      std::uint32_t frames = 0;
      for (const auto& e : fs::directory_iterator(store_.JobDir(req.job_id()) / "frames", ec))
        frames += e.path().extension() == ".pb";
      s->set_frames_spooled(frames);
      s->set_message("stream open without V: the plan is computed when it ends (V is estimated from every camera)");
      return out;
    }
    if (!job) return ErrorEnvelope(pb::ERROR_UNKNOWN_JOB, "unknown job '" + req.job_id() + "'", req.job_id());
    pb::Envelope ack = NewEnvelope(job->id);
    ack.mutable_ack();
    switch (req.body_case()) {
      case pb::Envelope::kStatus: {
        pb::Envelope out = NewEnvelope(job->id);
        *out.mutable_job_status() = Status(*job);
        return out;
      }
      case pb::Envelope::kExportRequest:
        return HandleExport(*job, req.export_request(), deferred);
      case pb::Envelope::kCancel: {
        if (!job->Ended()) {
          store_.WriteText(job->id, "cancelled", "");
          EndJob(*job, pb::STATE_CANCELLED, "cancelled by the user");
        }
        pb::Envelope out = NewEnvelope(job->id);  // the state after the request (a job that ended stays as it was)
        *out.mutable_job_status() = Status(*job);
        return out;
      }
      case pb::Envelope::kTaskResult:
        return HandleTaskResult(*job, req.task_result(), Worker(peer_key, req.task_result().worker()));
      case pb::Envelope::kJobCreated:
        job->last_ingest = Clock::now();
        return ack;  // FindJob loaded it
      case pb::Envelope::kFrameSpooled: {
        const int k = static_cast<int>(req.frame_spooled().index());
        if (!job->active) return ack;
        job->last_ingest = Clock::now();
        if (k < 0 || k >= job->n) return ErrorEnvelope(pb::ERROR_BAD_REQUEST, "frame " + std::to_string(k) + " out of range", job->id);
        if (!store_.HasFrame(job->id, k))
          return ErrorEnvelope(pb::ERROR_BAD_REQUEST, "frame " + std::to_string(k) + " is not in the job store", job->id);
        if (!job->frame_ok[k]) job->frame_ok[k] = 1, ++job->frames_spooled;  // duplicates are no-ops
        return ack;
      }
      case pb::Envelope::kIngestDone:
        if (!job->active) return ack;
        job->ingest_done = true;
        if (job->state == pb::STATE_INGESTING) job->state = pb::STATE_RUNNING;
        for (int k = 0; k < job->n; ++k)  // frames whose notice was lost
          if (!job->frame_ok[k] && store_.HasFrame(job->id, k)) job->frame_ok[k] = 1, ++job->frames_spooled;
        if (job->frames_spooled < job->n)
          EndJob(*job, pb::STATE_FAILED, "ingest ended with " + std::to_string(job->frames_spooled) + " frames for " +
                                             std::to_string(job->n) + " views");
        return ack;
      case pb::Envelope::kIngestFailed:
        if (!job->Ended()) EndJob(*job, pb::STATE_FAILED, req.ingest_failed().message());
        return ack;
      default:
        return ErrorEnvelope(pb::ERROR_BAD_REQUEST, "lfrecon-aggregate does not serve '" + BodyName(req) + "'", req.job_id());
    }
  } catch (const InputError& e) {
    return ErrorEnvelope(pb::ERROR_INPUT, e.what(), req.job_id());
  } catch (const std::exception& e) {
    spdlog::error("aggregate: {} request failed: {}", BodyName(req), e.what());
    return ErrorEnvelope(pb::ERROR_INTERNAL, e.what(), req.job_id());
  }
}

void Aggregator::Serve() {
  zmq::context_t context(1);
  RouterServer server(context, options_.endpoint, options_.max_message_bytes, options_.security);
  spdlog::info("aggregate: serving on {} (store {}, lease {} ms)", options_.endpoint, store_.root().string(),
               options_.lease_ms);
  if (!options_.security.curve())
    spdlog::warn("aggregate: no CURVE keys: task results are matched to their leases by the worker name they "
                 "give, which any peer that reaches {} can claim", options_.endpoint);
  // Exports run off this thread, one at a time per lane (plain, refined), in
  // arrival order; each is answered when its work is done.
  struct Pending {
    RouterServer::Incoming in;
    Work work;
  };
  struct LaneQueue {
    std::deque<Pending> pending;
    std::future<pb::Envelope> running;
  };
  LaneQueue lanes[2];
  auto reap = [&](LaneQueue& q, bool wait) {
    if (!q.running.valid()) return;
    if (!wait && q.running.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return;
    server.Reply(q.pending.front().in, q.running.get());
    q.pending.pop_front();
  };
  while (!StopRequested()) {
    bool busy = false;
    for (LaneQueue& q : lanes) {
      reap(q, false);
      if (!q.running.valid() && !q.pending.empty()) q.running = std::async(std::launch::async, q.pending.front().work);
      busy = busy || !q.pending.empty();
    }
    for (auto& [id, job] : jobs_) {
      GrowStream(*job);  // an open stream's new frames, its end or failure
      Reap(*job);        // fusion finished (outputs written) or failed
    }
    auto in = server.Receive(std::chrono::milliseconds(busy ? 20 : 200));
    if (!in) continue;
    pb::Envelope reply;
    if (!in->ok) {
      spdlog::warn("aggregate: refused a message of {} bytes: {}", in->bytes, in->error.message());
      reply = NewEnvelope();
      *reply.mutable_error() = in->error;
    } else {
      Deferred deferred;
      reply = Handle(in->envelope, &deferred, in->peer_key);
      if (deferred.work) {
        LaneQueue& q = lanes[deferred.lane == Lane::kRefine ? 1 : 0];
        if (static_cast<int>(q.pending.size()) < options_.max_queued_exports) {
          q.pending.push_back({std::move(*in), std::move(deferred.work)});
          continue;
        }
        reply = ErrorEnvelope(pb::ERROR_BUSY,
                              std::to_string(q.pending.size()) + " exports are queued (--max-queued-exports " +
                                  std::to_string(options_.max_queued_exports) + "); ask again later",
                              in->envelope.job_id());
      }
    }
    server.Reply(*in, reply);
  }
  // The fusion threads stop after the view each is integrating (what is queued
  // stays in the store for a restart); an export under way is answered (a
  // refined one stops at its next view or finishes refining), queued ones get an error.
  for (auto& [id, job] : jobs_) StopFusion(*job, false);
  for (LaneQueue& q : lanes) {
    reap(q, true);
    for (Pending& p : q.pending)
      server.Reply(p.in, ErrorEnvelope(pb::ERROR_INTERNAL, "lfrecon-aggregate stopped", p.in.envelope.job_id()));
  }
  for (auto& [id, job] : jobs_) StopFusion(*job, true);
  spdlog::info("aggregate: stopped");
}

}  // namespace lfrecon::svc
