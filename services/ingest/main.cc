// lfrecon-ingest: accepts jobs (SubmitJob), reads their video or images and
// poses (io/Dataset: COLMAP or transforms.json, validation, undistortion),
// writes the job manifest and spools every undistorted frame to the job store,
// announcing each to the aggregator (FrameSpooled), then IngestDone (or
// IngestFailed with the message that names the bad file). One thread per job;
// a cancelled job stops at its next frame.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <functional>
#include <iostream>
#include <list>
#include <memory>
#include <thread>

#include "common/job_store.h"
#include "common/messaging.h"
#include "io/dataset.h"
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
  ServerSecurity security;      // of the bound socket
  ClientSecurity to_aggregate;  // of the connections to the aggregator (the same key, role ingest)
};

// Refuses a submitted path outside every --data-root (after resolving "..",
// "." and symbolic links, so neither can leave a root). The message names
// the field, not what the path holds.
void CheckUnderDataRoots(const std::vector<std::filesystem::path>& roots, const std::string& field,
                         const std::string& path) {
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
        spdlog::warn("ingest: job {}: aggregator refused {}: {}", id, BodyName(env), reply->error().message());
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
    auto frames = ds->OpenFrames();
    Frame frame;
    Timer timer;
    for (int k = 0; k < ds->NumViews(); ++k) {
      if (StopRequested()) return;
      if (store.ReadText(id, "cancelled")) {
        spdlog::info("ingest: job {} cancelled after {} frames", id, spooled);
        return;
      }
      if (resume && store.HasFrame(id, k)) {
        ++kept;
      } else {
        if (resume) frame = frames->Read(k);
        else if (!frames->Next(&frame)) break;
        store.WriteFrame(id, FrameToProto(k, frame.image, CameraToProto(ds->View(k), ds->views()[k].name)));
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
    spdlog::info("ingest: job {}: {} frames spooled in {:.1f} s", id, spooled, timer.Seconds());
  } catch (const std::exception& e) {
    spdlog::error("ingest: job {}: {}", id, e.what());
    pb::Envelope env = NewEnvelope(id);
    env.mutable_ingest_failed()->set_message(e.what());
    Notify(agg, env, store, id);
  }
}

// A submission refused for now (a bound is reached).
struct Busy : std::runtime_error {
  using std::runtime_error::runtime_error;
};

// Jobs in the store that have not ended (no status.pb).
int UnfinishedJobs(const JobStore& store) {
  int n = 0;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(store.root(), ec)) {
    const std::string id = e.path().filename().string();
    n += store.Exists(id) && !std::filesystem::exists(e.path() / "status.pb");
  }
  return n;
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
  // Jobs a killed ingest left unfinished (no ingest.done, not ended): spooled on from where they stopped.
  for (const auto& e : std::filesystem::directory_iterator(store.root())) {
    const std::string id = e.path().filename().string();
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
      spdlog::error("ingest: cannot resume job {}: {}", id, ex.what());
      const std::string why = std::string("ingest restarted and cannot resume the job: ") + ex.what();
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
    auto in = server.Receive(std::chrono::milliseconds(200));
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
        if (static_cast<int>(spoolers.size()) >= o.max_ingest_threads)
          throw Busy(std::to_string(spoolers.size()) + " jobs are being spooled (--max-ingest-threads " +
                     std::to_string(o.max_ingest_threads) + "); submit again later");
        const int unfinished = UnfinishedJobs(store);
        if (unfinished >= o.max_jobs)
          throw Busy(std::to_string(unfinished) + " jobs in the store have not ended (--max-jobs " +
                     std::to_string(o.max_jobs) + "); submit again later");
        CheckUnderDataRoots(o.data_roots, "dataset_dir", spec.dataset_dir());
        CheckUnderDataRoots(o.data_roots, "images_dir", spec.images_dir());
        CheckUnderDataRoots(o.data_roots, "video_path", spec.video_path());
        CheckUnderDataRoots(o.data_roots, "colmap_dir", spec.colmap_dir());
        CheckUnderDataRoots(o.data_roots, "transforms_path", spec.transforms_path());
        auto ds = std::make_shared<Dataset>(Dataset::Open(ToDatasetOptions(spec)));
        // Every option validated (with V) before the job is accepted.
        JobFusionOptions(JobPipelineOptions(spec.options()), ds->bbox());
        // Frames (12 bytes a pixel) and sparse and dense maps (9 each) in the store.
        double bytes = 0;
        for (int k = 0; k < ds->NumViews(); ++k)
          bytes += 30.0 * ds->views()[k].camera.width * ds->views()[k].camera.height;
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
        spdlog::info("ingest: job {}: {} views ({}, V from {})", id, ds->NumViews(), ds->pose_source(), ds->bbox_source());
        reply = NewEnvelope(id);
        reply.mutable_submit_reply()->set_job_id(id);
        reply.mutable_submit_reply()->set_num_views(ds->NumViews());
      } catch (const Busy& e) {
        reply = ErrorEnvelope(pb::ERROR_BUSY, e.what());
      } catch (const InputError& e) {
        reply = ErrorEnvelope(pb::ERROR_INPUT, e.what());
      } catch (const OptionError& e) {
        reply = ErrorEnvelope(pb::ERROR_BAD_REQUEST, e.what());
      } catch (const std::exception& e) {
        reply = ErrorEnvelope(pb::ERROR_INTERNAL, e.what());
      }
    } else {
      reply = ErrorEnvelope(pb::ERROR_BAD_REQUEST, "lfrecon-ingest does not serve '" + BodyName(in->envelope) + "'",
                            in->envelope.job_id());
    }
    server.Reply(*in, reply);
  }
  for (auto& s : spoolers) s.thread.join();
  spdlog::info("ingest: stopped");
  return 0;
}

}  // namespace
}  // namespace lfrecon::svc

int main(int argc, char** argv) {
  lfrecon::UseMmapForLargeBlocks();
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
  if (o.max_jobs < 1 || o.max_ingest_threads < 1 || !(o.job_quota_gb > 0) || o.frame_delay_ms < 0) {
    std::cerr << "lfrecon-ingest: --max-jobs and --max-ingest-threads must be >= 1, --job-quota-gb > 0\n";
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
