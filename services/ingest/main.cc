// lfrecon-ingest: accepts jobs (SubmitJob), reads their video or images and
// poses (io/Dataset: COLMAP or transforms.json, validation, undistortion),
// writes the job manifest and spools every undistorted frame to the job store,
// announcing each to the aggregator (FrameSpooled), then IngestDone (or
// IngestFailed with the message that names the bad file). One thread per job;
// a cancelled job stops at its next frame.
// Client-pushed streams (StreamOpen, StreamFrame, StreamEnd; proto/README.md
// "Streams"): each open stream has a writer thread and a queue bounded by the
// credits it granted; a frame is answered (its credit returned) once it is
// stored; at the end of the stream the manifest is written (the plan is the
// aggregator's, from all the cameras) and the job handed to the aggregator.
// A stream that gives V is the aggregator's from its opening on: it plans and
// processes the views as their frames arrive (services/aggregate/stream_plan.cc).
// The frames are stored as the submit path stores them (common/job_store.h),
// each with its object mask when the dataset has masks (Frame.mask; checked
// against the frame's camera like the frame itself).
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <functional>
#include <map>
#include <mutex>
#include <set>
#include <iostream>
#include <list>
#include <memory>
#include <thread>

#include "common/job_store.h"
#include "common/messaging.h"
#include "io/dataset.h"
#include "io/input_text.h"
#include "util/memory.h"
#include "util/error.h"
#include "util/logging.h"
#include "util/progress.h"

namespace lfrecon::svc {
namespace {

struct IngestOptions {
  std::string endpoint = kDefaultIngestEndpoint;
  std::string aggregate = kDefaultAggregateEndpoint;
  std::filesystem::path store;
  std::int64_t max_message_bytes = kDefaultMaxMessageBytes;
  int frame_delay_ms = 0;  // fault injection (tests): a pause after each spooled frame
  // Bounds (deploy/README.md "Bounds"): jobs not ended in the store, jobs
  // spooling at once (one thread each), and the store bytes one job may take.
  int max_jobs = 16;
  int max_ingest_threads = 4;
  double job_quota_gb = 100;
  // Submitted paths must lie under one of these (canonical) folders; empty:
  // anywhere this daemon can read (a warning at start).
  std::vector<std::filesystem::path> data_roots;
  // Streams (client-pushed jobs): credits granted at most, frame indices below
  // max_stream_frames, and a stream that hears nothing from its client for
  // stream_timeout_s fails (the client died or went away).
  int max_stream_credits = 32;
  int max_stream_frames = 100000;
  double stream_timeout_s = 60;
  ServerSecurity security;      // of the bound socket
  ClientSecurity to_aggregate;  // of the connections to the aggregator (the same key, role ingest)
};

// Text for the log and a job's status that a client or peer influences (an
// exception's text with a client's paths, the aggregator's error reply, a
// stream's failure): printable ASCII, bounded (PeerText), so it cannot forge
// log lines or carry kilobytes into every line.
constexpr std::size_t kMaxReasonChars = 1024;
std::string Reason(const std::string& text) { return PeerText(text, kMaxReasonChars); }

// Refuses a submitted path that holds control characters (a newline or an
// escape would reach every log line that names the dataset or its files), or
// that lies outside every --data-root (after resolving "..", "." and symbolic
// links, so neither can leave a root). The message names the field, not what
// the path holds.
void CheckSubmittedPath(const std::vector<std::filesystem::path>& roots, const std::string& field,
                        const std::string& path) {
  if (std::any_of(path.begin(), path.end(), [](char c) { return static_cast<unsigned char>(c) < 0x20 || c == 0x7f; }))
    throw InputError(field, "a path with control characters (newline, escape, ...) is refused");
  if (roots.empty() || path.empty()) return;
  std::error_code ec;
  const std::filesystem::path p = std::filesystem::weakly_canonical(std::filesystem::absolute(path), ec);
  if (!ec)
    for (const std::filesystem::path& root : roots) {
      auto r = root.begin(), q = p.begin();
      while (r != root.end() && q != p.end() && *r == *q) ++r, ++q;
      if (r == root.end() || (std::next(r) == root.end() && r->empty())) return;
    }
  throw InputError(path, field + " is not under any --data-root of this ingest daemon");
}

// Sends `env` to the aggregator until it answers (or the daemon stops / the job is cancelled).
bool Notify(RequestClient& client, const pb::Envelope& env, const JobStore& store, const std::string& id) {
  while (!StopRequested()) {
    auto reply = client.Request(env, std::chrono::milliseconds(2000));
    if (reply) {
      if (reply->has_error())
        spdlog::warn("ingest: job {}: aggregator refused {}: {}", id, BodyName(env),
                     Reason(reply->error().message()));
      return true;
    }
    if (store.ReadText(id, "cancelled")) return false;
    spdlog::warn("ingest: job {}: aggregator {} not answering; retrying", id, client.endpoint());
  }
  return false;
}

// Spools the frames of job `id`. `resume`: a job this daemon (or a previous run
// of it, killed) had started: frames already in the store are kept and only
// announced again, the others are read (random access) and spooled.
void Spool(zmq::context_t& context, const IngestOptions& o, const JobStore& store, const std::string& id,
           std::shared_ptr<Dataset> ds, bool resume) {
  RequestClient agg(context, o.aggregate, o.max_message_bytes, o.to_aggregate);
  int spooled = 0, kept = 0;
  try {
    StoreFrameEncoder frames(*ds);
    Timer timer;
    double bytes = 0;
    for (int k = 0; k < ds->NumViews(); ++k) {
      if (StopRequested()) return;
      if (store.ReadText(id, "cancelled")) {
        spdlog::info("ingest: job {} cancelled after {} frames", id, spooled);
        return;
      }
      if (resume && store.HasFrame(id, k)) {
        ++kept;
      } else {
        // As on disk (validated by decoding it once), or a video frame as 8-bit PNG.
        const pb::Frame frame = frames.Encode(k, true);  // with its mask when the dataset has masks
        bytes += static_cast<double>(frame.data().size() + frame.mask().size());
        store.WriteFrame(id, frame);
        if (o.frame_delay_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(o.frame_delay_ms));
      }
      ++spooled;
      pb::Envelope env = NewEnvelope(id);
      env.mutable_frame_spooled()->set_index(k);
      if (!Notify(agg, env, store, id)) return;
    }
    if (resume) spdlog::info("ingest: job {} resumed: {} frames were in the store already", id, kept);
    store.WriteText(id, "ingest.done", std::to_string(spooled));
    pb::Envelope env = NewEnvelope(id);
    env.mutable_ingest_done()->set_num_frames(spooled);
    Notify(agg, env, store, id);
    spdlog::info("ingest: job {}: {} frames spooled in {:.1f} s ({:.0f} bytes a frame)", id, spooled, timer.Seconds(),
                 spooled - kept > 0 ? bytes / (spooled - kept) : 0.0);
  } catch (const std::exception& e) {
    const std::string why = Reason(e.what());
    spdlog::error("ingest: job {}: {}", id, why);
    pb::Envelope env = NewEnvelope(id);
    env.mutable_ingest_failed()->set_message(why);
    Notify(agg, env, store, id);
  }
}

// A submission refused for now (a bound is reached).
struct Busy : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Jobs in the store that have not ended (no status.pb), open streams included.
int UnfinishedJobs(const JobStore& store) {
  int n = 0;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(store.root(), ec)) {
    const std::string id = e.path().filename().string();
    const bool job = store.Exists(id) || (JobStore::ValidJobId(id) && std::filesystem::exists(e.path() / "stream.pb"));
    n += job && !std::filesystem::exists(e.path() / "status.pb");
  }
  return n;
}

// Refuses a new job (Busy) while `busy` ingest threads (the ones `what` names)
// reach --max-ingest-threads or the store's unfinished jobs reach --max-jobs;
// `again` ends the message ("submit again later").
void CheckAdmission(int busy, const std::string& what, const JobStore& store, const IngestOptions& o,
                    const std::string& again) {
  if (busy >= o.max_ingest_threads)
    throw Busy(std::to_string(busy) + " jobs are being " + what + " (--max-ingest-threads " +
               std::to_string(o.max_ingest_threads) + "); " + again);
  const int unfinished = UnfinishedJobs(store);
  if (unfinished >= o.max_jobs)
    throw Busy(std::to_string(unfinished) + " jobs in the store have not ended (--max-jobs " +
               std::to_string(o.max_jobs) + "); " + again);
}

// The error reply for what a request's handling threw: Busy, an input error
// (`input_code`: a submit's files are ERROR_INPUT, a stream's fields
// ERROR_BAD_REQUEST), a bad option, anything else.
pb::Envelope RequestErrorReply(pb::ErrorCode input_code) {
  try {
    throw;
  } catch (const Busy& e) {
    return ErrorEnvelope(pb::ERROR_BUSY, e.what());
  } catch (const InputError& e) {
    return ErrorEnvelope(input_code, e.what());
  } catch (const OptionError& e) {
    return ErrorEnvelope(pb::ERROR_BAD_REQUEST, e.what());
  } catch (const std::exception& e) {
    return ErrorEnvelope(pb::ERROR_INTERNAL, e.what());
  }
}

using Clock = std::chrono::steady_clock;

// A stream's end recorded by ingest (the aggregator never loaded the job): status.pb, FAILED.
void FailStreamJob(const JobStore& store, const std::string& id, int stored, const std::string& reason) {
  const std::string why = Reason(reason);
  pb::JobStatus st;
  st.set_state(pb::STATE_FAILED);
  st.set_frames_spooled(static_cast<std::uint32_t>(stored));
  st.set_message(why);
  try {
    store.WriteText(id, "status.pb", st.SerializeAsString());
  } catch (const std::exception& e) {
    spdlog::error("ingest: stream {}: cannot record its failure: {}", id, Reason(e.what()));
  }
  spdlog::error("ingest: stream {} failed: {}", id, why);
}

// An open client-pushed stream. The serving thread receives its messages and
// sends every reply; the writer thread stores the queued frames and ends the job.
struct Stream {
  std::string id;
  pb::StreamOpen open;
  int credits = 8;
  Clock::time_point last_message = Clock::now();
  bool end_received = false;  // serving thread only
  std::mutex mu;              // guards what follows
  std::condition_variable cv;
  std::deque<RouterServer::Incoming> queue;  // frames (and the end) to store, in arrival order
  std::deque<std::pair<RouterServer::Incoming, pb::Envelope>> replies;  // answered, to send
  std::set<std::uint32_t> indices;  // received (queued or stored)
  int unanswered = 0;               // frames received and not yet answered (their credits)
  int max_in_flight = 0;
  int stored = 0;
  std::uint64_t bytes = 0;
  bool abandon = false;     // the client went away: the writer fails the job and stops
  std::string closed_why;   // non-empty: ended or failed, further frames refused
  std::atomic<bool> done{false};
  std::thread thread;
};

// The frame as the client sent it, with the job's intrinsics and source camera where it has none.
pb::Frame WithStreamDefaults(const pb::StreamOpen& open, pb::Frame f) {
  pb::Camera* c = f.mutable_camera();
  if (c->k_size() == 0 && open.has_intrinsics()) {
    c->set_width(open.intrinsics().width());
    c->set_height(open.intrinsics().height());
    *c->mutable_k() = open.intrinsics().k();
  }
  const bool encoded = f.encoding() == "png" || f.encoding() == "jpeg";
  if (!f.has_source() && encoded && open.has_source()) *f.mutable_source() = open.source();
  return f;
}

// The writer thread of a stream: stores its frames in arrival order (any index
// order), answers each with its credit; at the end writes the manifest and
// hands the job to the aggregator.
void StreamWriter(zmq::context_t& context, const IngestOptions& o, const JobStore& store, std::shared_ptr<Stream> st) {
  Stream& s = *st;
  const std::string& id = s.id;
  RequestClient agg(context, o.aggregate, o.max_message_bytes, o.to_aggregate);
  std::map<std::uint32_t, pb::Camera> cameras;  // stored frames
  bool frame_masks = false;                     // a stored frame carried a mask (JobManifest.frame_masks)
  Timer timer;
  auto answer = [&](RouterServer::Incoming in, pb::Envelope reply) {
    std::lock_guard<std::mutex> lk(s.mu);
    s.replies.emplace_back(std::move(in), std::move(reply));
  };
  auto fail = [&](const std::string& why) {
    FailStreamJob(store, id, static_cast<int>(cameras.size()), why);
    std::lock_guard<std::mutex> lk(s.mu);
    s.closed_why = why;
  };
  // A stream that gives V is the aggregator's job from now on: it plans its
  // views as frames arrive (it reads them from the store). One try: an
  // aggregator that is down finds the stream in the store when it starts.
  if (SpecVolume(s.open.spec())) {
    pb::Envelope created = NewEnvelope(id);
    created.mutable_job_created();
    if (!agg.Request(created, std::chrono::milliseconds(2000)))
      spdlog::warn("ingest: stream {}: the aggregator did not answer; it finds the stream in the store when it starts",
                   id);
  }
  for (;;) {
    RouterServer::Incoming in;
    {
      std::unique_lock<std::mutex> lk(s.mu);
      while (s.queue.empty() && !s.abandon && !StopRequested()) s.cv.wait_for(lk, std::chrono::milliseconds(200));
      if (StopRequested()) break;
      if (s.abandon) {
        lk.unlock();
        fail("the client sent nothing for " + std::to_string(static_cast<int>(o.stream_timeout_s)) + " s after " +
             std::to_string(cameras.size()) + " frames, before the end of the stream (client gone)");
        break;
      }
      in = std::move(s.queue.front());
      s.queue.pop_front();
    }
    if (in.envelope.has_stream_end()) {
      // Every frame before it is stored: the frames must be 0..n-1, no gaps.
      const std::uint32_t n = static_cast<std::uint32_t>(cameras.size());
      std::string why;
      if (n == 0) why = "the stream ended without frames";
      else if (cameras.rbegin()->first + 1 != n) {
        std::uint32_t missing = 0;
        while (cameras.count(missing)) ++missing;
        why = "the stream ended with " + std::to_string(n) + " frames but indices up to " +
              std::to_string(cameras.rbegin()->first) + ": frame " + std::to_string(missing) + " (and maybe more) missing";
      } else if (in.envelope.stream_end().num_frames() > 0 && in.envelope.stream_end().num_frames() != n)
        why = "the client pushed " + std::to_string(in.envelope.stream_end().num_frames()) + " frames, " +
              std::to_string(n) + " arrived";
      pb::JobManifest m;
      if (why.empty()) {
        try {
          m.set_job_id(id);
          *m.mutable_spec() = s.open.spec();
          std::vector<PinholeView> views;
          std::vector<DatasetView> dviews;
          for (const auto& [k, c] : cameras) {
            *m.add_views() = c;
            views.push_back(CameraFromProto(c, "frame " + std::to_string(k)));
            DatasetView dv;
            dv.index = static_cast<int>(k);
            const PinholeView& v = views.back();
            dv.camera = Camera::Pinhole(v.width, v.height, v.K(0, 0), v.K(1, 1), v.K(0, 2), v.K(1, 2));
            dv.cam_from_world = Rigid3d(Eigen::Quaterniond(v.R), v.t);
            dviews.push_back(dv);
          }
          BoundingBox volume;
          if (s.open.spec().bbox_size() == 6) {
            const auto& b = s.open.spec().bbox();
            volume.min = Eigen::Vector3d(b[0], b[1], b[2]);
            volume.max = Eigen::Vector3d(b[3], b[4], b[5]);
            m.set_bbox_source("--bbox");
          } else {
            volume = EstimateBoundingBox(dviews);
            m.set_bbox_source("estimated");
          }
          *m.mutable_volume() = BoxToProto(volume);
          m.set_pose_source("stream");
          m.set_frame_masks(frame_masks);
          // The job's plan, as the aggregator will compute it: refused here if it cannot be.
          ReconstructionPlan::Compute(views, volume, JobPipelineOptions(s.open.spec().options()));
          store.WriteText(id, "ingest.done", std::to_string(n));
          store.WriteManifest(m);
        } catch (const std::exception& e) {
          why = Reason(e.what());
        }
      }
      if (!why.empty()) {
        fail(why);
        answer(std::move(in), ErrorEnvelope(pb::ERROR_INPUT, why, id));
        break;
      }
      pb::Envelope created = NewEnvelope(id);
      created.mutable_job_created()->set_num_views(n);
      Notify(agg, created, store, id);
      pb::Envelope done = NewEnvelope(id);
      done.mutable_ingest_done()->set_num_frames(n);
      Notify(agg, done, store, id);
      std::uint64_t bytes;
      int max_in_flight;
      {
        std::lock_guard<std::mutex> lk(s.mu);
        bytes = s.bytes;
        max_in_flight = s.max_in_flight;
        s.closed_why = "the stream has ended";
      }
      spdlog::info("ingest: stream {}: {} frames stored in {:.1f} s ({:.0f} bytes a frame, at most {} in flight)", id, n,
                   timer.Seconds(), static_cast<double>(bytes) / n, max_in_flight);
      pb::Envelope reply = NewEnvelope(id);
      reply.mutable_stream_ended()->set_num_frames(n);
      reply.mutable_stream_ended()->set_max_in_flight(static_cast<std::uint32_t>(max_in_flight));
      reply.mutable_stream_ended()->set_bytes_stored(bytes);
      answer(std::move(in), reply);
      break;
    }
    const std::uint32_t k = in.envelope.stream_frame().frame().index();
    const std::string what = "stream " + id + " frame " + std::to_string(k);
    pb::Envelope reply;
    try {
      pb::Frame f = CompactFrameProto(WithStreamDefaults(s.open, in.envelope.stream_frame().frame()), what);
      const PinholeView view = CameraFromProto(f.camera(), what);
      // Validated as the workers will read it: image header against the camera before decoding, then decoded.
      FrameFromProto(f, view.width, view.height, what);
      // Its mask, if any, as the aggregator's fusion will read it: PNG header against the camera, then decoded.
      MaskFromProto(f, view.width, view.height, what);
      const std::uint64_t frame_bytes = f.data().size() + f.mask().size();
      const double quota = o.job_quota_gb * 1e9;
      std::uint64_t bytes_before;
      {
        std::lock_guard<std::mutex> lk(s.mu);
        bytes_before = s.bytes;
      }
      if (static_cast<double>(bytes_before + frame_bytes) > quota)
        throw InputError(what, "the job's frames exceed the per-job quota (--job-quota-gb " +
                                   std::to_string(o.job_quota_gb) + ")");
      store.WriteFrame(id, f);
      cameras[k] = f.camera();
      frame_masks = frame_masks || !f.mask().empty();
      if (o.frame_delay_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(o.frame_delay_ms));
      reply = NewEnvelope(id);
      pb::StreamCredit* c = reply.mutable_stream_credit();
      std::lock_guard<std::mutex> lk(s.mu);
      ++s.stored;
      s.bytes += frame_bytes;
      c->set_index(k);
      c->set_frames_stored(static_cast<std::uint32_t>(s.stored));
      c->set_in_flight(static_cast<std::uint32_t>(s.unanswered));
      c->set_max_in_flight(static_cast<std::uint32_t>(s.max_in_flight));
    } catch (const std::exception& e) {  // refused, not stored: the client may push it again
      reply = ErrorEnvelope(pb::ERROR_INPUT, e.what(), id);
      std::lock_guard<std::mutex> lk(s.mu);
      s.indices.erase(k);
    }
    answer(std::move(in), reply);
  }
  s.done = true;
}

int Serve(const IngestOptions& o) {
  zmq::context_t context(1);
  JobStore store(o.store);
  // One ingest per store: a second would spool the same unfinished jobs again.
  const auto store_lock = LockStoreForIngest(store);
  if (const int n = RemoveIngestTempFiles(store))  // a killed ingest's half-written files
    spdlog::info("ingest: removed {} temporary files a previous ingest left in the store", n);
  RouterServer server(context, o.endpoint, o.max_message_bytes, o.security);
  RequestClient agg(context, o.aggregate, o.max_message_bytes, o.to_aggregate);
  // One thread per job being spooled; finished ones are joined as they end.
  struct Spooler {
    std::thread thread;
    std::shared_ptr<std::atomic<bool>> done;
  };
  std::list<Spooler> spoolers;
  auto start = [&spoolers](std::function<void()> work) {
    auto done = std::make_shared<std::atomic<bool>>(false);
    spoolers.push_back({std::thread([work = std::move(work), done] {
                          work();
                          *done = true;
                        }),
                        done});
  };
  auto reap = [&spoolers] {
    for (auto it = spoolers.begin(); it != spoolers.end();) {
      if (!*it->done) {
        ++it;
        continue;
      }
      it->thread.join();
      it = spoolers.erase(it);
    }
  };
  // Open streams: the serving thread sends every reply (its socket is its own).
  std::map<std::string, std::shared_ptr<Stream>> streams;
  auto flush_streams = [&] {
    bool pending = false;
    for (auto it = streams.begin(); it != streams.end();) {
      Stream& st = *it->second;
      std::deque<std::pair<RouterServer::Incoming, pb::Envelope>> out;
      {
        std::lock_guard<std::mutex> lk(st.mu);
        out.swap(st.replies);
        for (const auto& r : out)
          if (r.first.envelope.has_stream_frame()) --st.unanswered;  // its credit goes back with the reply
        pending = pending || !st.queue.empty() || st.unanswered > 0 || st.end_received;
      }
      for (auto& [in, reply] : out) server.Reply(in, reply);
      if (!st.end_received && !st.done && Clock::now() - st.last_message > std::chrono::duration<double>(o.stream_timeout_s)) {
        std::lock_guard<std::mutex> lk(st.mu);
        st.abandon = true;
        st.cv.notify_one();
      }
      if (st.done) {
        st.thread.join();
        std::lock_guard<std::mutex> lk(st.mu);
        for (auto& [in, reply] : st.replies) server.Reply(in, reply);
        for (auto& in : st.queue)
          server.Reply(in, ErrorEnvelope(pb::ERROR_BAD_REQUEST, "stream " + st.id + ": " + st.closed_why, st.id));
        it = streams.erase(it);
        continue;
      }
      ++it;
    }
    return pending;
  };
  // Jobs a killed ingest left unfinished (no ingest.done, not ended): spooled on from where they stopped.
  for (const auto& e : std::filesystem::directory_iterator(store.root())) {
    const std::string id = e.path().filename().string();
    if (JobStore::ValidJobId(id) && !store.Exists(id) && std::filesystem::exists(e.path() / "stream.pb") &&
        !std::filesystem::exists(e.path() / "status.pb")) {
      // A stream open when this daemon stopped: its client lost the connection; the job fails, it never waits.
      FailStreamJob(store, id, 0, "lfrecon-ingest restarted while the stream was open; push the frames again as a new job");
      continue;
    }
    if (!store.Exists(id)) continue;
    if (store.ReadText(id, "ingest.done") || store.ReadText(id, "status.pb") || store.ReadText(id, "cancelled")) continue;
    try {
      const pb::JobManifest m = store.ReadManifest(id);
      auto ds = std::make_shared<Dataset>(Dataset::Open(ToDatasetOptions(m.spec())));
      if (ds->NumViews() != m.views_size())
        throw InputError(m.spec().dataset_dir(), "now has " + std::to_string(ds->NumViews()) + " views, the job " +
                                                     std::to_string(m.views_size()));
      spdlog::info("ingest: resuming job {} ({} views)", id, ds->NumViews());
      start([&context, &o, &store, id, ds] { Spool(context, o, store, id, ds, true); });
    } catch (const std::exception& ex) {  // the job fails with the reason, it does not wait for ever
      spdlog::error("ingest: cannot resume job {}: {}", id, Reason(ex.what()));
      const std::string why = "ingest restarted and cannot resume the job: " + Reason(ex.what());
      start([&context, &o, &store, id, why] {
        RequestClient to(context, o.aggregate, o.max_message_bytes, o.to_aggregate);
        pb::Envelope env = NewEnvelope(id);
        env.mutable_ingest_failed()->set_message(why);
        Notify(to, env, store, id);
      });
    }
  }
  spdlog::info("ingest: serving on {} (store {}, aggregator {})", o.endpoint, store.root().string(), o.aggregate);
  while (!StopRequested()) {
    reap();
    const bool pending = flush_streams();
    auto in = server.Receive(std::chrono::milliseconds(pending ? 1 : streams.empty() ? 200 : 20));
    if (!in) continue;
    pb::Envelope reply;
    if (!in->ok) {
      spdlog::warn("ingest: refused a message of {} bytes: {}", in->bytes, in->error.message());
      reply = NewEnvelope();
      *reply.mutable_error() = in->error;
    } else if (in->envelope.has_ping()) {
      reply = NewEnvelope();
      reply.mutable_pong()->set_daemon("lfrecon-ingest");
    } else if (in->envelope.has_submit()) {
      const pb::JobSpec& spec = in->envelope.submit().spec();
      try {
        CheckAdmission(static_cast<int>(spoolers.size()), "spooled", store, o, "submit again later");
        CheckSubmittedPath(o.data_roots, "dataset_dir", spec.dataset_dir());
        CheckSubmittedPath(o.data_roots, "images_dir", spec.images_dir());
        CheckSubmittedPath(o.data_roots, "video_path", spec.video_path());
        CheckSubmittedPath(o.data_roots, "colmap_dir", spec.colmap_dir());
        CheckSubmittedPath(o.data_roots, "transforms_path", spec.transforms_path());
        CheckSubmittedPath(o.data_roots, "masks_dir", spec.masks_dir());
        auto ds = std::make_shared<Dataset>(Dataset::Open(ToDatasetOptions(spec)));
        // Every option validated (with V) before the job is accepted.
        JobFusionOptions(JobPipelineOptions(spec.options()), ds->bbox());
        // Frames (encoded: at most 3 bytes a pixel as 8-bit PNG) and sparse and dense maps (9 each) in the store.
        double bytes = 0;
        for (int k = 0; k < ds->NumViews(); ++k)
          bytes += 21.0 * ds->views()[k].camera.width * ds->views()[k].camera.height;
        if (bytes > o.job_quota_gb * 1e9)
          throw InputError(spec.dataset_dir().empty() ? spec.images_dir() + spec.video_path() : spec.dataset_dir(),
                           "the job needs about " + std::to_string(static_cast<long>(bytes / 1e9 + 0.5)) +
                               " GB in the job store, more than the per-job quota (--job-quota-gb " +
                               std::to_string(o.job_quota_gb) + ")");
        const std::string id = store.CreateJob();
        store.WriteManifest(MakeManifest(id, spec, *ds));
        pb::Envelope created = NewEnvelope(id);
        created.mutable_job_created()->set_num_views(ds->NumViews());
        if (!agg.Request(created, std::chrono::milliseconds(5000)))
          spdlog::warn("ingest: aggregator {} did not answer; it will find job {} in the store", o.aggregate, id);
        start([&context, &o, &store, id, ds] { Spool(context, o, store, id, ds, false); });
        spdlog::info("ingest: job {}: {} views ({}, V from {}{})", id, ds->NumViews(), ds->pose_source(),
                     ds->bbox_source(), ds->HasMasks() ? ", masks from " + ds->mask_source() + " stored with the frames" : "");
        reply = NewEnvelope(id);
        reply.mutable_submit_reply()->set_job_id(id);
        reply.mutable_submit_reply()->set_num_views(ds->NumViews());
      } catch (const std::exception&) {
        reply = RequestErrorReply(pb::ERROR_INPUT);
      }
    } else if (in->envelope.has_stream_open()) {
      const pb::StreamOpen& open = in->envelope.stream_open();
      const pb::JobSpec& spec = open.spec();
      try {
        CheckAdmission(static_cast<int>(spoolers.size() + streams.size()), "spooled or streamed", store, o,
                       "open the stream again later");
        if (!spec.dataset_dir().empty() || !spec.images_dir().empty() || !spec.video_path().empty() ||
            !spec.colmap_dir().empty() || !spec.transforms_path().empty() || !spec.masks_dir().empty())
          throw OptionError("a stream names no paths: its client pushes the frames and cameras");
        const PipelineOptions po = JobPipelineOptions(spec.options());  // every option checked before the job exists
        if (const std::optional<BoundingBox> b = SpecVolume(spec)) JobFusionOptions(po, *b);
        if (open.has_intrinsics()) {
          pb::Camera c = open.intrinsics();
          c.clear_r(), c.clear_t();
          for (double v : {1., 0., 0., 0., 1., 0., 0., 0., 1.}) c.add_r(v);
          for (int k = 0; k < 3; ++k) c.add_t(0);
          CameraFromProto(c, "stream_open.intrinsics");
        }
        if (open.has_source()) SourceCameraFromProto(open.source(), "stream_open.source");
        auto st = std::make_shared<Stream>();
        st->open = open;
        st->credits = std::clamp<int>(open.credits() == 0 ? 8 : static_cast<int>(open.credits()), 1, o.max_stream_credits);
        st->id = store.CreateJob();
        store.WriteText(st->id, "stream.pb", open.SerializeAsString());
        st->thread = std::thread(StreamWriter, std::ref(context), std::cref(o), std::cref(store), st);
        streams[st->id] = st;
        spdlog::info("ingest: stream {} open ({} credits)", st->id, st->credits);
        reply = NewEnvelope(st->id);
        pb::StreamOpened* r = reply.mutable_stream_opened();
        r->set_job_id(st->id);
        r->set_credits(static_cast<std::uint32_t>(st->credits));
        r->set_max_frame_bytes(static_cast<std::uint64_t>(std::max<std::int64_t>(0, o.max_message_bytes - 65536)));
        r->set_max_frames(static_cast<std::uint32_t>(o.max_stream_frames));
      } catch (const std::exception&) {
        reply = RequestErrorReply(pb::ERROR_BAD_REQUEST);
      }
    } else if (in->envelope.has_stream_frame() || in->envelope.has_stream_end()) {
      const std::string& id = in->envelope.job_id();
      const auto it = streams.find(id);
      if (it == streams.end()) {
        reply = ErrorEnvelope(pb::ERROR_UNKNOWN_JOB, "no open stream '" + id + "' (it ended, failed or never was)", id);
      } else {
        Stream& st = *it->second;
        st.last_message = Clock::now();
        std::unique_lock<std::mutex> lk(st.mu);
        const pb::Frame& f = in->envelope.stream_frame().frame();
        if (!st.closed_why.empty()) {
          reply = ErrorEnvelope(pb::ERROR_BAD_REQUEST, "stream " + id + ": " + st.closed_why, id);
        } else if (st.end_received) {
          reply = ErrorEnvelope(pb::ERROR_BAD_REQUEST, "stream " + id + " has ended: no more frames", id);
        } else if (in->envelope.has_stream_end()) {
          st.end_received = true;  // answered once the frames before it are stored
          st.queue.push_back(std::move(*in));
          st.cv.notify_one();
          continue;
        } else if (st.unanswered >= st.credits) {
          reply = ErrorEnvelope(pb::ERROR_BUSY, "stream " + id + ": no credit (" + std::to_string(st.unanswered) +
                                                    " frames unanswered, " + std::to_string(st.credits) +
                                                    " granted): wait for a credit before the next frame", id);
        } else if (f.index() >= static_cast<std::uint32_t>(o.max_stream_frames)) {
          reply = ErrorEnvelope(pb::ERROR_BAD_REQUEST, "frame index " + std::to_string(f.index()) + " out of range [0, " +
                                                           std::to_string(o.max_stream_frames) + ")", id);
        } else if (st.indices.count(f.index())) {
          // Repeated index: the first copy is kept, this one ignored (its credit goes back at once).
          reply = NewEnvelope(id);
          reply.mutable_stream_credit()->set_index(f.index());
          reply.mutable_stream_credit()->set_repeated(true);
          reply.mutable_stream_credit()->set_frames_stored(static_cast<std::uint32_t>(st.stored));
          reply.mutable_stream_credit()->set_in_flight(static_cast<std::uint32_t>(st.unanswered + 1));
          reply.mutable_stream_credit()->set_max_in_flight(static_cast<std::uint32_t>(st.max_in_flight));
        } else {
          st.indices.insert(f.index());
          ++st.unanswered;
          st.max_in_flight = std::max(st.max_in_flight, st.unanswered);
          st.queue.push_back(std::move(*in));
          st.cv.notify_one();
          continue;
        }
      }
    } else {
      reply = ErrorEnvelope(pb::ERROR_BAD_REQUEST, "lfrecon-ingest does not serve '" + BodyName(in->envelope) + "'",
                            in->envelope.job_id());
    }
    server.Reply(*in, reply);
  }
  for (auto& [id, st] : streams) {
    {
      std::lock_guard<std::mutex> lk(st->mu);
      st->cv.notify_all();
    }
    st->thread.join();
  }
  for (auto& s : spoolers) s.thread.join();
  spdlog::info("ingest: stopped");
  return 0;
}

}  // namespace
}  // namespace lfrecon::svc

int main(int argc, char** argv) {
  lfrecon::ConfigureHeap();
  using namespace lfrecon::svc;
  CLI::App app{"lfrecon-ingest: reads, validates, undistorts and spools the frames of submitted jobs"};
  IngestOptions o;
  o.endpoint = EndpointFromEnv("LFRECON_INGEST", kDefaultIngestEndpoint);
  o.aggregate = EndpointFromEnv("LFRECON_AGGREGATE", kDefaultAggregateEndpoint);
  std::string store;
  double max_mb = kDefaultMaxMessageBytes / 1048576.0;
  int verbosity = 0;
  SecurityFlags security;
  AddServerSecurityFlags(&app, &security);
  security.server_key = EndpointFromEnv("LFRECON_AGGREGATE_KEY", "");
  app.add_option("--aggregate-key", security.server_key,
                 "The aggregator's public key file (.pub; default $LFRECON_AGGREGATE_KEY); this daemon connects "
                 "with its own --key, listed as role ingest in the aggregator's allow-list");
  app.add_option("--bind", o.endpoint, "ZeroMQ endpoint to bind (default: $LFRECON_INGEST or loopback)")->capture_default_str();
  app.add_option("--aggregate", o.aggregate, "The aggregator's endpoint")->capture_default_str();
  app.add_option("--store", store, "Job store folder")->required();
  std::vector<std::string> data_roots;
  app.add_option("--data-root", data_roots,
                 "Submitted datasets, images, videos and pose files must lie under this folder (repeatable; "
                 "symbolic links and '..' resolved). Without it any path this daemon can read is accepted");
  app.add_option("--frame-delay-ms", o.frame_delay_ms, "Fault injection (tests): pause after each spooled frame");
  app.add_option("--max-jobs", o.max_jobs, "Submissions are refused (ERROR_BUSY) while this many jobs have not ended")
      ->capture_default_str();
  app.add_option("--max-ingest-threads", o.max_ingest_threads,
                 "Jobs spooled at once (a thread each); more submissions are refused (ERROR_BUSY)")
      ->capture_default_str();
  app.add_option("--job-quota-gb", o.job_quota_gb,
                 "Largest job store footprint a job may have (frames and depth maps, estimated at submit)")
      ->capture_default_str();
  app.add_option("--max-stream-credits", o.max_stream_credits,
                 "Frames a streaming client may have in flight at most (it asks for its number; 0: 8)")
      ->capture_default_str();
  app.add_option("--max-stream-frames", o.max_stream_frames, "Frame indices of a stream are below this")
      ->capture_default_str();
  app.add_option("--stream-timeout-s", o.stream_timeout_s,
                 "A stream whose client sends nothing for this long before its end fails (the client died)")
      ->capture_default_str();
  app.add_option("--max-message-mb", max_mb, "Largest message accepted or sent, MiB")->capture_default_str();
  app.add_flag("-v,--verbose", verbosity, "More logging");
  CLI11_PARSE(app, argc, argv);
  lfrecon::SetupLogging(verbosity);
  o.store = store;
  for (const std::string& r : data_roots) {
    std::error_code ec;
    const std::filesystem::path root = std::filesystem::canonical(r, ec);
    if (ec || !std::filesystem::is_directory(root)) {
      std::cerr << "lfrecon-ingest: --data-root " << r << ": not a folder\n";
      return 2;
    }
    o.data_roots.push_back(root);
  }
  if (o.data_roots.empty())
    spdlog::warn("ingest: no --data-root: jobs may name any path this daemon can read");
  o.max_message_bytes = static_cast<std::int64_t>(max_mb * 1048576.0);
  if (o.max_jobs < 1 || o.max_ingest_threads < 1 || !(o.job_quota_gb > 0) || o.frame_delay_ms < 0 ||
      o.max_stream_credits < 1 || o.max_stream_frames < 1 || !(o.stream_timeout_s > 0)) {
    std::cerr << "lfrecon-ingest: --max-jobs, --max-ingest-threads, --max-stream-credits and --max-stream-frames must "
                 "be >= 1, --job-quota-gb and --stream-timeout-s > 0\n";
    return 2;
  }
  try {
    // --key serves both sockets: with --allow the bound one is a CURVE server; with
    // --aggregate-key the connections to the aggregator are CURVE clients.
    SecurityFlags bound = security;
    if (bound.allow.empty()) bound.key.clear();
    o.security = ResolveServerSecurity(bound);
    if (!security.server_key.empty() || !security.key.empty()) o.to_aggregate = ResolveClientSecurity(security);
    o.to_aggregate.insecure = security.insecure;
    CheckServerEndpoint(o.endpoint, o.security);
    CheckClientEndpoint(o.aggregate, o.to_aggregate);
  } catch (const lfrecon::OptionError& e) {
    std::cerr << "lfrecon-ingest: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "lfrecon-ingest: error: " << e.what() << "\n";
    return 1;
  }
  try {
    InstallStopHandlers();
    return Serve(o);
  } catch (const std::exception& e) {
    std::cerr << "lfrecon-ingest: error: " << e.what() << "\n";
    return 1;
  }
}
