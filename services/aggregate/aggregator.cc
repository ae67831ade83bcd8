#include "aggregator.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <condition_variable>
#include <deque>
#include <fstream>
#include <future>
#include <mutex>
#include <set>
#include <sstream>
#include <thread>

#include "depth/gradient_depth_estimator.h"
#include "depth/streaming_depth.h"
#include "fusion/mesh_coloring.h"
#include "io/ply.h"
#include "refine/refine.h"
#include "util/error.h"
#include "util/progress.h"

namespace lfrecon::svc {
namespace fs = std::filesystem;

struct Aggregator::Job {
  std::string id;
  pb::JobState state = pb::STATE_INGESTING;
  std::string message;
  Clock::time_point created = Clock::now();
  pb::JobStatus final_status;  // for jobs that ended (loaded from status.pb)
  // Running jobs only. The serving thread's:
  bool active = false;  // running: the fusion thread is up, results are taken
  JobGeometry geo;      // constant once loaded (the fusion thread reads it too)
  int n = 0;
  ViewGraph near, photo;
  std::vector<std::vector<int>> voters;  // per view: FilterVoters (sparse maps voting in its filter)
  std::vector<char> frame_ok, sparse_ok, dense_ok;
  int frames_spooled = 0, sparse_done = 0, dense_done = 0;  // dense_done: maps received (stored)
  bool ingest_done = false;
  std::map<std::pair<int, int>, std::pair<Clock::time_point, std::string>> leases;  // (stage, view) -> deadline, worker
  int leases_expired = 0;
  std::map<std::pair<int, int>, std::set<std::string>> leased_to;  // (stage, view) -> every worker given it
  struct Tries {
    int failures = 0;
    std::set<std::string> failed_on;  // workers it failed on
  };
  std::map<std::pair<int, int>, Tries> tries;
  int tasks_failed = 0;
  Clock::time_point last_ingest = Clock::now();  // JobCreated, FrameSpooled, IngestDone (or the load)
  // Shared with the job's fusion thread:
  std::mutex grid_mu;  // held while a view is integrated and while an export extracts its mesh
  std::unique_ptr<ProbabilisticFusion> fusion;  // guarded by grid_mu; released when the thread stops
  std::mutex queue_mu;                          // guards queue, fused (and stop's changes, for the wait)
  std::condition_variable queue_cv;
  std::deque<std::pair<int, bool>> queue;  // (view, append to fused.log): stored dense maps to fuse, in order
  std::atomic<bool> stop{false};
  std::vector<char> fused;
  std::vector<int> unreadable;  // stored dense maps the fusion thread could not read: done again
  std::atomic<int> views_fused{0};  // changes under grid_mu (with the grid)
  std::atomic<std::uint64_t> active_voxels{0};
  enum Outcome { kFusing = 0, kFinished = 1, kFailed = 2 };
  std::atomic<int> outcome{kFusing};  // kFinished: every view fused, outputs written
  std::string fusion_error;           // kFailed: why (written before outcome)
  std::uint32_t triangles = 0;        // kFinished: of mesh.ply (written before outcome)
  double seconds_outputs = 0;
  int replay = 0;  // views queued from the checkpoint when loaded
  std::thread thread;

  ~Job() { StopFusion(*this, true); }
  bool Ended() const {
    return state == pb::STATE_DONE || state == pb::STATE_FAILED || state == pb::STATE_CANCELLED;
  }
  bool FramesOk(int v, const std::vector<int>& nbs) const {
    if (!frame_ok[v]) return false;
    for (int j : nbs)
      if (!frame_ok[j]) return false;
    return true;
  }
};

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
    if (!store_.Exists(id) || store_.ReadText(id, "status.pb")) continue;
    jobs_[id] = LoadOrFail(id);
  }
}

Aggregator::~Aggregator() {
  for (auto& [id, job] : jobs_) StopFusion(*job, false);  // all stop together
  jobs_.clear();                                           // joins them
}

namespace {

// The job's fusion grid, empty: V, voxel and σ_s as the embedded pipeline sets them.
std::unique_ptr<ProbabilisticFusion> NewFusion(const JobGeometry& geo) {
  return std::make_unique<ProbabilisticFusion>(JobFusionOptions(geo.options, geo.volume));
}

// `k` of `n` views evenly spread, as the embedded pipeline picks its colour and
// carving frames over the views it processed (all of a job's).
std::vector<int> EvenlySpread(int n, int k) {
  std::vector<int> out;
  k = std::min(k, n);
  for (int c = 0; c < k; ++c) out.push_back(static_cast<int>(static_cast<std::size_t>(c) * n / k));
  return out;
}

// The frames `ids` that are in the store (`frame_ok`), as ColorViews; `cache`
// shares the pixels of frames read before.
std::vector<ColorView> LoadColorViews(const JobStore& store, const JobGeometry& geo, const std::vector<int>& ids,
                                      const std::vector<char>& frame_ok, std::map<int, cv::Mat>* cache) {
  std::vector<ColorView> out;
  for (int v : ids) {
    if (!frame_ok[v]) continue;
    auto it = cache->find(v);
    if (it == cache->end()) it = cache->emplace(v, store.ReadFrame(geo.id, v, geo.views[v])).first;
    out.push_back({geo.views[v], it->second, cv::Mat()});
  }
  return out;
}

// What a refined export needs, captured on the serving thread.
struct RefineSnapshot {
  std::string id;
  bool complete = false;    // the job is DONE: its whole checkpoint, mesh_refined.ply cached
  JobGeometry geo;          // running job (a finished one's is read from the store)
  std::vector<char> fused;  // running job: the views fused so far
  std::vector<char> frame_ok;
};

// The export reply of the refined mesh: the grid rebuilt from the checkpoint's
// dense maps in view order (not fused.log's arrival order: the same sums up to
// float rounding, and the same result whatever order the workers delivered,
// so a finished job's export is reproducible), then what `lfrecon run` does
// after fusion (libs/pipeline/embedded_pipeline.cc): RefineFusedSurface with
// `carving_views` evenly spread frames, the fused iso-surface where Poisson
// made nothing, colour from `color_views` frames.
pb::Envelope RefinedExportReply(const JobStore& store, RefineSnapshot snap) {
  Timer total;
  const fs::path dir = store.JobDir(snap.id);
  const fs::path cached = dir / "mesh_refined.ply";
  pb::Envelope out = NewEnvelope(snap.id);
  pb::ExportReply* rep = out.mutable_export_reply();
  rep->set_complete(snap.complete);
  if (snap.complete && fs::exists(cached)) {
    const TriangleMesh mesh = ReadPly(cached);
    rep->set_ply(ReadFileBytes(cached));
    rep->set_vertices(mesh.vertices.size());
    rep->set_triangles(mesh.triangles.size());
    if (auto st = store.ReadText(snap.id, "status.pb")) {
      pb::JobStatus s;
      if (s.ParseFromString(*st)) rep->set_views_fused(s.views_fused());
    }
    return out;
  }
  if (snap.complete) {  // the grid was released when the job ended: its checkpoint, every view
    snap.geo = LoadJobGeometry(store, snap.id);
    const int n = static_cast<int>(snap.geo.views.size());
    snap.fused.assign(n, 0);
    if (auto log = store.ReadText(snap.id, "fused.log")) {
      std::istringstream ss(*log);
      int v;
      while (ss >> v)
        if (v >= 0 && v < n) snap.fused[v] = 1;
    }
    snap.frame_ok.assign(n, 0);
    for (int k = 0; k < n; ++k) snap.frame_ok[k] = store.HasFrame(snap.id, k);
  }
  const JobGeometry& geo = snap.geo;
  const PipelineOptions& po = geo.options;
  const int n = static_cast<int>(geo.views.size());
  Timer tf;
  std::unique_ptr<ProbabilisticFusion> fusion = NewFusion(geo);
  int fused = 0;
  for (int v = 0; v < n; ++v) {
    if (!snap.fused[v]) continue;
    if (StopRequested()) throw std::runtime_error("lfrecon-aggregate is stopping");
    fusion->Integrate(geo.views[v], store.ReadMap(snap.id, pb::MAP_DENSE, v, geo.views[v]), v);
    ++fused;
  }
  const double seconds_fusion = tf.Seconds();
  TriangleMesh mesh;
  RefineStats rs;
  std::map<int, cv::Mat> frames;
  if (fused > 0) {
    const int kc = po.refine && po.refine_options.carve ? po.carving_views : 0;
    const std::vector<ColorView> carve = LoadColorViews(store, geo, EvenlySpread(n, kc), snap.frame_ok, &frames);
    if (po.refine) {
      RefineResult refined = RefineFusedSurface(*fusion, carve, po.refine_options, po.meshing);
      rs = refined.stats;
      mesh = std::move(refined.mesh);
    }
    // Too few boundary voxels for Poisson: the fused surface rather than nothing (as lfrecon run).
    if (mesh.triangles.empty()) mesh = fusion->ExtractMesh(po.meshing);
  }
  fusion.reset();
  if (po.color_views > 0 && !mesh.triangles.empty()) {
    const std::vector<ColorView> cviews =
        LoadColorViews(store, geo, EvenlySpread(n, po.color_views), snap.frame_ok, &frames);
    if (!cviews.empty()) ColorizeMesh(&mesh, cviews, po.coloring);
  }
  frames.clear();
  const fs::path tmp = dir / ("export_refined_" + std::to_string(::getpid()) + ".ply");
  WritePly(mesh, tmp);
  rep->set_ply(ReadFileBytes(tmp));
  if (snap.complete) CommitFile(tmp, cached);  // atomic and durable: a reader sees all of it or nothing
  else fs::remove(tmp);
  rep->set_vertices(mesh.vertices.size());
  rep->set_triangles(mesh.triangles.size());
  rep->set_views_fused(fused);
  spdlog::info("aggregate: job {}: refined export of {} fused views: {} triangles from {} carving views ({} carved), "
               "{:.1f} s ({:.1f} re-fusing the checkpoint, {:.1f} refining)",
               snap.id, fused, mesh.triangles.size(), rs.carving_views, rs.carved, total.Seconds(),
               seconds_fusion, rs.seconds_total);
  return out;
}

// The fused mesh with colour from the embedded pipeline's colour frames
// (color_views evenly spread over the views), those of `frame_ok` read from the store.
void ColourMesh(const JobStore& store, const JobGeometry& geo, const std::vector<char>& frame_ok, TriangleMesh* mesh) {
  const PipelineOptions& po = geo.options;
  if (po.color_views <= 0 || mesh->triangles.empty()) return;
  std::map<int, cv::Mat> frames;
  const int n = static_cast<int>(geo.views.size());
  const std::vector<ColorView> cviews = LoadColorViews(store, geo, EvenlySpread(n, po.color_views), frame_ok, &frames);
  if (!cviews.empty()) ColorizeMesh(mesh, cviews, po.coloring);
}

}  // namespace

std::unique_ptr<Aggregator::Job> Aggregator::LoadOrFail(const std::string& id) {
  try {
    return LoadJob(id);
  } catch (const std::exception& e) {
    auto job = std::make_unique<Job>();
    job->id = id;
    EndJob(*job, pb::STATE_FAILED, std::string("cannot load the job: ") + e.what());
    return job;
  }
}

std::unique_ptr<Aggregator::Job> Aggregator::LoadJob(const std::string& id) {
  auto job = std::make_unique<Job>();
  job->id = id;
  if (auto st = store_.ReadText(id, "status.pb")) {
    if (!job->final_status.ParseFromString(*st)) throw InputError((store_.JobDir(id) / "status.pb").string(), "corrupt");
    job->state = job->final_status.state();
    job->message = job->final_status.message();
    return job;
  }
  job->geo = LoadJobGeometry(store_, id);
  const int n = job->n = static_cast<int>(job->geo.views.size());
  const PipelineOptions& po = job->geo.options;
  std::vector<Eigen::Vector3d> dirs;
  for (const auto& v : job->geo.views) dirs.push_back(v.ViewingDirection());
  job->near = ViewGraph(dirs, po.depth.gradient.max_view_angle_deg, po.depth.max_frame_gap);
  job->photo = ViewGraph(dirs, po.propagation.photo.max_view_angle_deg, po.depth.max_frame_gap);
  const std::vector<char> on_grid = HierarchyGrid(job->geo.views, po.depth.gradient);
  job->voters.resize(n);
  const ViewGraph wide(dirs, po.depth.filter.max_view_angle_deg, po.depth.max_frame_gap);
  for (int v = 0; v < n; ++v) job->voters[v] = FilterVoters(wide, on_grid, v);
  job->frame_ok.assign(n, 0);
  job->sparse_ok.assign(n, 0);
  job->dense_ok.assign(n, 0);
  job->fused.assign(n, 0);
  // What a crash (or a power loss before the store synced its files) left: a
  // stored file too short to hold its view is removed and that view done again.
  const fs::path dir = store_.JobDir(id);
  for (const char* sub : {"sparse", "dense"}) {  // this daemon's temporary files (it holds the store's lock)
    std::error_code ec;
    for (const auto& e : fs::directory_iterator(dir / sub, ec))
      if (e.path().filename().string().find(".tmp") != std::string::npos) fs::remove(e.path(), ec);
  }
  auto intact = [&](const fs::path& p, std::uintmax_t min_bytes) {
    std::error_code ec;
    const std::uintmax_t size = fs::file_size(p, ec);
    if (ec) return false;
    if (size >= min_bytes) return true;
    spdlog::warn("aggregate: job {}: {} holds {} bytes, at least {} expected: removed", id, p.string(), size, min_bytes);
    fs::remove(p, ec);
    return false;
  };
  int bad_frame = -1;
  for (int k = 0; k < n; ++k) {
    const std::uintmax_t pixels = static_cast<std::uintmax_t>(job->geo.views[k].width) * job->geo.views[k].height;
    if (store_.HasFrame(id, k)) {
      if (intact(store_.FramePath(id, k), pixels * 12)) job->frame_ok[k] = 1, ++job->frames_spooled;
      else if (bad_frame < 0) bad_frame = k;
    }
    if (store_.HasMap(id, pb::MAP_SPARSE, k) && intact(store_.MapPath(id, pb::MAP_SPARSE, k), pixels * 4))
      job->sparse_ok[k] = 1, ++job->sparse_done;
    if (store_.HasMap(id, pb::MAP_DENSE, k)) intact(store_.MapPath(id, pb::MAP_DENSE, k), pixels * 4);
  }
  job->ingest_done = store_.ReadText(id, "ingest.done").has_value();
  if (job->ingest_done) job->state = pb::STATE_RUNNING;
  job->fusion = NewFusion(job->geo);
  job->active = true;
  // Checkpoint: the fusion thread replays the fused views in their order,
  // then fuses (and logs) any dense map that was stored but not yet logged.
  if (auto log = store_.ReadText(id, "fused.log")) {
    std::istringstream ss(*log);
    int v;
    while (ss >> v)
      if (v >= 0 && v < n && !job->dense_ok[v] && store_.HasMap(id, pb::MAP_DENSE, v)) {
        Enqueue(*job, v, false);
        ++job->replay;
      }
  }
  int unlogged = 0;
  for (int v = 0; v < n; ++v)
    if (!job->dense_ok[v] && store_.HasMap(id, pb::MAP_DENSE, v)) Enqueue(*job, v, true), ++unlogged;
  spdlog::info("aggregate: job {} loaded: {} views, {} frames, {} sparse, {} dense maps to fuse ({} from fused.log, "
               "{} stored after it)",
               id, n, job->frames_spooled, job->sparse_done, job->dense_done, job->replay, unlogged);
  if (store_.ReadText(id, "cancelled")) {  // cancelled, then stopped before status.pb was written
    EndJob(*job, pb::STATE_CANCELLED, "cancelled by the user");
    job->fusion.reset();
    return job;
  }
  if (bad_frame >= 0 && job->ingest_done) {  // ingest will not send it again
    EndJob(*job, pb::STATE_FAILED, "frame " + std::to_string(bad_frame) + " in the job store is corrupt");
    job->fusion.reset();
    return job;
  }
  job->thread = std::thread(&Aggregator::FusionLoop, this, job.get());
  return job;
}

Aggregator::Job* Aggregator::FindJob(const std::string& id) {
  const auto it = jobs_.find(id);
  if (it != jobs_.end()) {
    Reap(*it->second);
    return it->second.get();
  }
  if (!store_.Exists(id)) return nullptr;
  auto job = LoadOrFail(id);
  Job* p = job.get();
  jobs_[id] = std::move(job);
  return p;
}

// Serving thread: the dense map of `view` is in the store; it is fused after those queued before it.
void Aggregator::Enqueue(Job& job, int view, bool log) const {
  if (!job.dense_ok[view]) job.dense_ok[view] = 1, ++job.dense_done;
  {
    std::lock_guard<std::mutex> lk(job.queue_mu);
    job.queue.emplace_back(view, log);
  }
  job.queue_cv.notify_one();
}

void Aggregator::StopFusion(Job& job, bool join) {
  {
    std::lock_guard<std::mutex> lk(job.queue_mu);
    job.stop = true;
  }
  job.queue_cv.notify_all();
  if (join && job.thread.joinable()) job.thread.join();
}

void Aggregator::FusionLoop(Job* jp) const {
  Job& job = *jp;
  const std::string& id = job.id;
  const PipelineOptions& po = job.geo.options;
  Timer replay_timer;
  int done = 0;
  try {
    for (;;) {
      std::pair<int, bool> item;
      {
        std::unique_lock<std::mutex> lk(job.queue_mu);
        // A signal cannot notify: look at StopRequested() now and then.
        while (!job.stop && !StopRequested() && (job.queue.empty() || job.outcome != Job::kFusing))
          job.queue_cv.wait_for(lk, std::chrono::milliseconds(200));
        if (job.stop || StopRequested()) break;
        item = job.queue.front();
        job.queue.pop_front();
        if (job.fused[item.first]) continue;
      }
      const int v = item.first;
      DepthMap map;
      try {
        map = store_.ReadMap(id, pb::MAP_DENSE, v, job.geo.views[v]);
      } catch (const InputError& e) {  // a map the store lost (a crash): the view is done again
        spdlog::warn("aggregate: job {}: stored dense map of view {} unreadable ({}): removed, re-issued", id, v,
                     e.what());
        std::error_code ec;
        fs::remove(store_.MapPath(id, pb::MAP_DENSE, v), ec);
        std::lock_guard<std::mutex> lk(job.queue_mu);
        job.unreadable.push_back(v);
        continue;
      }
      {
        std::lock_guard<std::mutex> grid(job.grid_mu);
        job.fusion->Integrate(job.geo.views[v], map, v);
        for (int slept = 0; slept < options_.fusion_delay_ms && !job.stop && !StopRequested(); slept += 10)
          std::this_thread::sleep_for(std::chrono::milliseconds(10));  // fault injection (tests)
        job.active_voxels = job.fusion->Stats().active_voxels;
        if (item.second) store_.AppendLine(id, "fused.log", std::to_string(v));  // before anyone sees it fused
        {
          std::lock_guard<std::mutex> lk(job.queue_mu);
          job.fused[v] = 1;
        }
        ++job.views_fused;
      }
      if (++done == job.replay && job.replay > 0)
        spdlog::info("aggregate: job {}: {} views replayed from the checkpoint in {:.1f} s", id, job.replay,
                     replay_timer.Seconds());
      if (job.views_fused < job.n) continue;
      // Every view fused: the job's outputs. The grid is complete and no other
      // thread changes it, so exports may read it meanwhile.
      Timer t;
      const fs::path dir = store_.JobDir(id);
      std::vector<char> frame_ok(job.n, 0);
      for (int k = 0; k < job.n; ++k) frame_ok[k] = store_.HasFrame(id, k);
      const TriangleMesh raw = job.fusion->ExtractMesh(po.meshing);
      // Each output atomically and durably (temporary name, fsync, rename): DONE means they are whole.
      auto write_ply = [&](const TriangleMesh& m, const fs::path& path) {
        const fs::path tmp = TempPathFor(path);
        try {
          WritePly(m, tmp);
        } catch (...) {
          std::error_code ec;
          fs::remove(tmp, ec);
          throw;
        }
        CommitFile(tmp, path);
      };
      write_ply(raw, dir / "mesh_raw.ply");
      TriangleMesh mesh = raw;
      ColourMesh(store_, job.geo, frame_ok, &mesh);
      write_ply(mesh, dir / "mesh.ply");
      if (po.write_vdb) {
        const fs::path tmp = TempPathFor(dir / "grid.vdb");
        try {
          job.fusion->WriteVdb(tmp);
        } catch (...) {
          std::error_code ec;
          fs::remove(tmp, ec);
          throw;
        }
        CommitFile(tmp, dir / "grid.vdb");
      }
      job.triangles = static_cast<std::uint32_t>(mesh.triangles.size());
      job.seconds_outputs = t.Seconds();
      job.outcome = Job::kFinished;  // the serving thread marks the job DONE (Reap)
    }
  } catch (const std::exception& e) {
    job.fusion_error = e.what();
    job.outcome = Job::kFailed;
    spdlog::error("aggregate: job {}: fusion failed: {}", id, e.what());
  }
  std::size_t left;
  {
    std::lock_guard<std::mutex> lk(job.queue_mu);
    left = job.queue.size();
  }
  {
    std::lock_guard<std::mutex> grid(job.grid_mu);
    job.fusion.reset();  // the grid's memory goes back; what is not fused yet is in the store
  }
  spdlog::info("aggregate: job {}: fusion thread stopped, {} views fused{}", id, job.views_fused.load(),
               left ? ", " + std::to_string(left) + " stored maps not fused (a restart fuses them)" : "");
}

void Aggregator::Reap(Job& job) {
  if (!job.active) return;
  std::vector<int> unreadable;
  {
    std::lock_guard<std::mutex> lk(job.queue_mu);
    unreadable.swap(job.unreadable);
  }
  for (int v : unreadable)
    if (job.dense_ok[v]) job.dense_ok[v] = 0, --job.dense_done;
  if (!job.ingest_done && Clock::now() - job.last_ingest > std::chrono::duration<double>(options_.ingest_timeout_s)) {
    EndJob(job, pb::STATE_FAILED,
           "nothing from ingest for " + std::to_string(static_cast<int>(options_.ingest_timeout_s)) + " s after " +
               std::to_string(job.frames_spooled) + " of " + std::to_string(job.n) +
               " frames (lfrecon-ingest died and did not resume the job)");
    return;
  }
  const int outcome = job.outcome;
  if (outcome == Job::kFailed) {
    EndJob(job, pb::STATE_FAILED, "fusion: " + job.fusion_error);
  } else if (outcome == Job::kFinished) {
    spdlog::info("aggregate: job {}: {} views fused, mesh {} triangles ({:.1f} s)", job.id, job.views_fused.load(),
                 job.triangles, job.seconds_outputs);
    EndJob(job, pb::STATE_DONE, "");
  }
}

pb::JobStatus Aggregator::Status(const Job& job) const {
  if (!job.active && job.final_status.state() != pb::STATE_UNKNOWN) return job.final_status;
  pb::JobStatus s;
  s.set_state(job.state);
  s.set_num_views(job.n);
  s.set_frames_spooled(job.frames_spooled);
  s.set_sparse_done(job.sparse_done);
  s.set_dense_done(job.dense_done);
  s.set_views_fused(job.views_fused);
  s.set_message(job.message);
  s.set_seconds(std::chrono::duration<double>(Clock::now() - job.created).count());
  s.set_active_voxels(static_cast<std::uint32_t>(job.active_voxels));
  s.set_leases_expired(job.leases_expired);
  s.set_tasks_failed(job.tasks_failed);
  if (job.state == pb::STATE_DONE) s.set_triangles(job.triangles);
  return s;
}

void Aggregator::EndJob(Job& job, pb::JobState state, const std::string& message) {
  job.state = state;
  job.message = message;
  job.leases.clear();
  job.final_status = Status(job);
  job.active = false;
  StopFusion(job, false);  // it stops after the view it is integrating, and releases the grid
  try {
    store_.WriteText(job.id, "status.pb", job.final_status.SerializeAsString());
  } catch (const std::exception& e) {  // a full disk: the job ends anyway; a restart loads it again
    spdlog::error("aggregate: job {}: cannot record its end: {}", job.id, e.what());
  }
  if (state == pb::STATE_FAILED) spdlog::error("aggregate: job {} failed: {}", job.id, message);
  else spdlog::info("aggregate: job {} {}", job.id, pb::JobState_Name(state));
}

void Aggregator::ExpireLeases(Job& job) {
  const auto now = Clock::now();
  std::vector<std::pair<std::pair<int, int>, std::string>> expired;
  for (auto it = job.leases.begin(); it != job.leases.end();) {
    if (it->second.first < now) {
      expired.emplace_back(it->first, it->second.second);
      it = job.leases.erase(it);
    } else {
      ++it;
    }
  }
  for (const auto& [key, worker] : expired) {
    ++job.leases_expired;
    if (FailTask(job, key.first, key.second, worker,
                 "not returned by " + worker + " within its lease of " + std::to_string(options_.lease_ms) + " ms"))
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

pb::Envelope Aggregator::HandleTaskRequest(const pb::Envelope& req) {
  const pb::TaskRequest& tr = req.task_request();
  const int stage = tr.stage();
  if (stage != pb::STAGE_DEPTH && stage != pb::STAGE_PROPAGATE)
    return ErrorEnvelope(pb::ERROR_BAD_REQUEST, "unknown stage " + std::to_string(stage));
  auto& seen = seen_workers_[stage];
  if (seen.size() > 1000) {  // forget workers gone for a minute
    const auto old = Clock::now() - std::chrono::seconds(60);
    for (auto it = seen.begin(); it != seen.end();) it = it->second < old ? seen.erase(it) : std::next(it);
  }
  seen[tr.worker()] = Clock::now();
  const bool others = OtherWorkerAlive(stage, tr.worker());
  for (auto& [id, jp] : jobs_) {
    Job& job = *jp;
    if (!job.active) continue;
    ExpireLeases(job);
    if (!job.active) continue;  // a task failed too often
    for (int v = 0; v < job.n; ++v) {
      if (job.leases.count({stage, v})) continue;
      if (others) {  // a task that failed on this worker goes to another one
        const auto t = job.tries.find({stage, v});
        if (t != job.tries.end() && t->second.failed_on.count(tr.worker())) continue;
      }
      pb::Envelope out = NewEnvelope(id);
      pb::Task* task = out.mutable_task();
      if (stage == pb::STAGE_DEPTH) {
        if (job.sparse_ok[v] || !job.FramesOk(v, job.near.Neighbors(v))) continue;
        task->add_frames(v);
        for (int j : job.near.Neighbors(v)) task->add_frames(j);
      } else {
        if (job.dense_ok[v] || !job.sparse_ok[v]) continue;
        const std::vector<int>& voters = job.voters[v];
        bool ready = true;
        for (int j : voters) ready = ready && job.sparse_ok[j];
        if (!ready) continue;
        task->add_frames(v);
        if (job.geo.options.densify) {
          if (!job.FramesOk(v, job.photo.Neighbors(v))) continue;
          for (int j : job.photo.Neighbors(v)) task->add_frames(j);
        }
        for (int j : voters) task->add_voters(j);
      }
      task->set_stage(static_cast<pb::Stage>(stage));
      task->set_view(v);
      task->set_lease_ms(options_.lease_ms);
      job.leases[{stage, v}] = {Clock::now() + std::chrono::milliseconds(options_.lease_ms), tr.worker()};
      job.leased_to[{stage, v}].insert(tr.worker());
      spdlog::debug("aggregate: job {}: {} of view {} -> {}", id, stage == pb::STAGE_DEPTH ? "depth" : "propagate", v,
                    tr.worker());
      return out;
    }
  }
  pb::Envelope out = NewEnvelope();
  out.mutable_no_task()->set_retry_ms(options_.retry_ms);
  return out;
}

pb::Envelope Aggregator::HandleTaskResult(Job& job, const pb::TaskResult& r) {
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
  const std::pair<int, int> key{static_cast<int>(r.stage()), v};
  const std::string task = std::string(r.stage() == pb::STAGE_DEPTH ? "depth" : "propagate") + " of view " +
                           std::to_string(v);
  const auto given = job.leased_to.find(key);
  if (given == job.leased_to.end() || !given->second.count(r.worker()))
    return ErrorEnvelope(pb::ERROR_BAD_REQUEST, task + " was not leased to '" + r.worker() + "'", job.id);
  const bool done = r.stage() == pb::STAGE_DEPTH ? job.sparse_ok[v] : job.dense_ok[v];
  const auto lease = job.leases.find(key);
  if (!r.error().empty()) {
    if (lease != job.leases.end() && lease->second.second == r.worker()) job.leases.erase(lease);
    if (!done) FailTask(job, key.first, v, r.worker(), r.worker() + ": " + r.error());
    pb::Envelope ack = NewEnvelope(job.id);
    ack.mutable_ack();
    return ack;
  }
  const std::string what = "task result of view " + std::to_string(v) + " from " + r.worker();
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

Aggregator::Work Aggregator::RefinedExport(const Job& job) const {
  RefineSnapshot snap;
  snap.id = job.id;
  snap.complete = job.state == pb::STATE_DONE;
  if (!snap.complete) {
    snap.geo = job.geo;
    {
      std::lock_guard<std::mutex> lk(const_cast<Job&>(job).queue_mu);
      snap.fused = job.fused;
    }
    snap.frame_ok = job.frame_ok;
  }
  return [store = store_, snap = std::move(snap)]() -> pb::Envelope {
    try {
      return RefinedExportReply(store, snap);
    } catch (const InputError& e) {
      return ErrorEnvelope(pb::ERROR_INPUT, e.what(), snap.id);
    } catch (const std::exception& e) {
      spdlog::error("aggregate: job {}: refined export failed: {}", snap.id, e.what());
      return ErrorEnvelope(pb::ERROR_INTERNAL, e.what(), snap.id);
    }
  };
}

// The mesh of what is fused so far: extracted under the grid's lock (whole
// views only), coloured after it. A finished job's is mesh.ply.
Aggregator::Work Aggregator::PlainExport(Job& job) const {
  const bool done = job.state == pb::STATE_DONE;
  return [store = store_, job = &job, done, views_fused = job.final_status.views_fused(),
          frame_ok = done ? std::vector<char>() : job.frame_ok]() mutable -> pb::Envelope {
    const std::string& id = job->id;
    try {
      pb::Envelope out = NewEnvelope(id);
      pb::ExportReply* rep = out.mutable_export_reply();
      const fs::path dir = store.JobDir(id);
      TriangleMesh mesh;
      bool complete = done;
      if (!done) {
        std::unique_lock<std::mutex> grid(job->grid_mu);
        if (!job->fusion) {  // the job ended meanwhile and its grid is gone
          grid.unlock();
          pb::JobStatus s;
          if (auto st = store.ReadText(id, "status.pb")) s.ParseFromString(*st);
          if (s.state() != pb::STATE_DONE)
            return ErrorEnvelope(pb::ERROR_BAD_REQUEST,
                                 "job " + id + " is " + pb::JobState_Name(s.state()) + ": nothing to export", id);
          complete = true, views_fused = s.views_fused();
        } else {
          mesh = job->fusion->ExtractMesh(job->geo.options.meshing);
          views_fused = job->views_fused;
          complete = job->outcome == Job::kFinished;
        }
      }
      if (complete && mesh.triangles.empty() && fs::exists(dir / "mesh.ply")) {
        mesh = ReadPly(dir / "mesh.ply");
        rep->set_ply(ReadFileBytes(dir / "mesh.ply"));
      } else {
        ColourMesh(store, job->geo, frame_ok, &mesh);
        const fs::path tmp = dir / ("export_" + std::to_string(::getpid()) + "_" +
                                    std::to_string(std::hash<std::thread::id>()(std::this_thread::get_id())) + ".ply");
        WritePly(mesh, tmp);
        rep->set_ply(ReadFileBytes(tmp));
        fs::remove(tmp);
      }
      rep->set_vertices(mesh.vertices.size());
      rep->set_triangles(mesh.triangles.size());
      rep->set_views_fused(views_fused);
      rep->set_complete(complete);
      return out;
    } catch (const InputError& e) {
      return ErrorEnvelope(pb::ERROR_INPUT, e.what(), id);
    } catch (const std::exception& e) {
      spdlog::error("aggregate: job {}: export failed: {}", id, e.what());
      return ErrorEnvelope(pb::ERROR_INTERNAL, e.what(), id);
    }
  };
}

pb::Envelope Aggregator::HandleExport(Job& job, const pb::ExportRequest& req, Deferred* deferred) {
  if (job.state != pb::STATE_DONE && !job.active)
    return ErrorEnvelope(pb::ERROR_BAD_REQUEST,
                         "job " + job.id + " is " + pb::JobState_Name(job.state) + ": nothing to export", job.id);
  Work work = req.refine() ? RefinedExport(job) : PlainExport(job);
  if (!deferred) return work();
  deferred->work = std::move(work);
  deferred->lane = req.refine() ? Lane::kRefine : Lane::kExport;
  return pb::Envelope();
}

pb::Envelope Aggregator::Handle(const pb::Envelope& req) { return Handle(req, nullptr); }

pb::Envelope Aggregator::Handle(const pb::Envelope& req, Deferred* deferred) {
  try {
    switch (req.body_case()) {
      case pb::Envelope::kPing: {
        pb::Envelope out = NewEnvelope();
        out.mutable_pong()->set_daemon("lfrecon-aggregate");
        return out;
      }
      case pb::Envelope::kTaskRequest:
        return HandleTaskRequest(req);
      default:
        break;
    }
    // Everything else names a job.
    if (!JobStore::ValidJobId(req.job_id()))
      return ErrorEnvelope(pb::ERROR_UNKNOWN_JOB, "invalid job id '" + req.job_id() + "'", req.job_id());
    Job* job = FindJob(req.job_id());
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
        return HandleTaskResult(*job, req.task_result());
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
    for (auto& [id, job] : jobs_) Reap(*job);  // fusion finished (outputs written) or failed
    auto in = server.Receive(std::chrono::milliseconds(busy ? 20 : 200));
    if (!in) continue;
    pb::Envelope reply;
    if (!in->ok) {
      spdlog::warn("aggregate: refused a message of {} bytes: {}", in->bytes, in->error.message());
      reply = NewEnvelope();
      *reply.mutable_error() = in->error;
    } else {
      Deferred deferred;
      reply = Handle(in->envelope, &deferred);
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
