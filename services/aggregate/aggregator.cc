#include "aggregator.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <deque>
#include <fstream>
#include <future>
#include <sstream>

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
  // Running jobs only:
  JobGeometry geo;
  int n = 0;
  ViewGraph near, wide, photo;
  std::vector<char> frame_ok, sparse_ok, dense_ok, fused;
  int frames_spooled = 0, sparse_done = 0, dense_done = 0, views_fused = 0;
  bool ingest_done = false;
  std::unique_ptr<ProbabilisticFusion> fusion;
  std::map<std::pair<int, int>, std::pair<Clock::time_point, std::string>> leases;  // (stage, view) -> deadline, worker
  int leases_expired = 0;

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
  // Resume every job the store holds that has not ended.
  for (const auto& e : fs::directory_iterator(store_.root())) {
    const std::string id = e.path().filename().string();
    if (!store_.Exists(id) || store_.ReadText(id, "status.pb")) continue;
    try {
      jobs_[id] = LoadJob(id);
    } catch (const std::exception& ex) {
      spdlog::error("aggregate: cannot resume job {}: {}", id, ex.what());
    }
  }
}

Aggregator::~Aggregator() = default;

namespace {

// The job's fusion grid, empty: V, voxel and σ_s as the embedded pipeline sets them.
std::unique_ptr<ProbabilisticFusion> NewFusion(const JobGeometry& geo) {
  const PipelineOptions& po = geo.options;
  FusionOptions fo = po.fusion;
  fo.volume = geo.volume;
  fo.voxel_size = PipelineVoxelSize(geo.volume, po);
  if (po.densify) fo.sigma_s = po.dense_sigma_s;
  return std::make_unique<ProbabilisticFusion>(fo);
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
  if (snap.complete) fs::rename(tmp, cached);  // atomic: a reader sees all of it or nothing
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

}  // namespace

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
  job->near = ViewGraph(dirs, po.depth.gradient.max_view_angle_deg);
  job->wide = ViewGraph(dirs, po.depth.filter.max_view_angle_deg);
  job->photo = ViewGraph(dirs, po.propagation.photo.max_view_angle_deg);
  job->frame_ok.assign(n, 0);
  job->sparse_ok.assign(n, 0);
  job->dense_ok.assign(n, 0);
  job->fused.assign(n, 0);
  for (int k = 0; k < n; ++k) {
    if (store_.HasFrame(id, k)) job->frame_ok[k] = 1, ++job->frames_spooled;
    if (store_.HasMap(id, pb::MAP_SPARSE, k)) job->sparse_ok[k] = 1, ++job->sparse_done;
  }
  job->ingest_done = store_.ReadText(id, "ingest.done").has_value();
  if (job->ingest_done) job->state = pb::STATE_RUNNING;
  job->fusion = NewFusion(job->geo);
  // Checkpoint: replay the fused views in their order, then any dense map
  // that was stored but not yet logged.
  int replayed = 0;
  Timer timer;
  if (auto log = store_.ReadText(id, "fused.log")) {
    std::istringstream ss(*log);
    int v;
    while (ss >> v)
      if (v >= 0 && v < n && !job->fused[v] && store_.HasMap(id, pb::MAP_DENSE, v)) {
        Integrate(*job, v, store_.ReadMap(id, pb::MAP_DENSE, v, job->geo.views[v]), false);
        ++replayed;
      }
  }
  for (int v = 0; v < n; ++v)
    if (!job->fused[v] && store_.HasMap(id, pb::MAP_DENSE, v))
      Integrate(*job, v, store_.ReadMap(id, pb::MAP_DENSE, v, job->geo.views[v]), true);
  if (store_.ReadText(id, "cancelled")) job->state = pb::STATE_CANCELLED;
  spdlog::info("aggregate: job {} loaded: {} views, {} frames, {} sparse, {} fused ({} replayed from the checkpoint in "
               "{:.1f} s)",
               id, n, job->frames_spooled, job->sparse_done, job->views_fused, replayed, timer.Seconds());
  MaybeFinish(*job);
  return job;
}

Aggregator::Job* Aggregator::FindJob(const std::string& id) {
  const auto it = jobs_.find(id);
  if (it != jobs_.end()) return it->second.get();
  if (!store_.Exists(id)) return nullptr;
  auto job = LoadJob(id);
  Job* p = job.get();
  jobs_[id] = std::move(job);
  return p;
}

void Aggregator::Integrate(Job& job, int view, const DepthMap& map, bool log) {
  if (!job.dense_ok[view]) job.dense_ok[view] = 1, ++job.dense_done;
  if (job.fused[view]) return;
  job.fusion->Integrate(job.geo.views[view], map, view);
  job.fused[view] = 1;
  ++job.views_fused;
  if (log) store_.AppendLine(job.id, "fused.log", std::to_string(view));
}

pb::JobStatus Aggregator::Status(const Job& job) const {
  if (job.Ended() && !job.fusion && job.final_status.state() != pb::STATE_UNKNOWN) return job.final_status;
  pb::JobStatus s;
  s.set_state(job.state);
  s.set_num_views(job.n);
  s.set_frames_spooled(job.frames_spooled);
  s.set_sparse_done(job.sparse_done);
  s.set_dense_done(job.dense_done);
  s.set_views_fused(job.views_fused);
  s.set_message(job.message);
  s.set_seconds(std::chrono::duration<double>(Clock::now() - job.created).count());
  if (job.fusion) s.set_active_voxels(static_cast<std::uint32_t>(job.fusion->Stats().active_voxels));
  s.set_leases_expired(job.leases_expired);
  return s;
}

void Aggregator::EndJob(Job& job, pb::JobState state, const std::string& message) {
  job.state = state;
  job.message = message;
  job.leases.clear();
  job.final_status = Status(job);
  store_.WriteText(job.id, "status.pb", job.final_status.SerializeAsString());
  job.fusion.reset();  // the grid's memory goes back; outputs are in the store
  if (state == pb::STATE_FAILED) spdlog::error("aggregate: job {} failed: {}", job.id, message);
  else spdlog::info("aggregate: job {} {}", job.id, pb::JobState_Name(state));
}

TriangleMesh Aggregator::CurrentMesh(Job& job, bool colour) {
  const PipelineOptions& po = job.geo.options;
  TriangleMesh mesh = job.fusion->ExtractMesh(po.meshing);
  if (!colour || po.color_views <= 0 || mesh.triangles.empty()) return mesh;
  // The frames the embedded pipeline colours from: color_views evenly spread over the views.
  std::vector<ColorView> cviews;
  const int k = std::min(po.color_views, job.n);
  for (int c = 0; c < k; ++c) {
    const int v = static_cast<int>(static_cast<std::size_t>(c) * job.n / k);
    if (!job.frame_ok[v]) continue;
    cviews.push_back({job.geo.views[v], store_.ReadFrame(job.id, v, job.geo.views[v]), cv::Mat()});
  }
  if (!cviews.empty()) ColorizeMesh(&mesh, cviews, po.coloring);
  return mesh;
}

void Aggregator::MaybeFinish(Job& job) {
  if (job.Ended() || !job.fusion || job.views_fused < job.n) return;
  Timer t;
  const fs::path dir = store_.JobDir(job.id);
  TriangleMesh raw = job.fusion->ExtractMesh(job.geo.options.meshing);
  WritePly(raw, dir / "mesh_raw.ply");
  const TriangleMesh mesh = CurrentMesh(job, true);
  WritePly(mesh, dir / "mesh.ply");
  if (job.geo.options.write_vdb) job.fusion->WriteVdb(dir / "grid.vdb");
  pb::JobStatus s = Status(job);
  spdlog::info("aggregate: job {}: {} views fused, mesh {} triangles ({:.1f} s)", job.id, job.views_fused,
               mesh.triangles.size(), t.Seconds());
  job.state = pb::STATE_DONE;
  EndJob(job, pb::STATE_DONE, "");
  job.final_status.set_triangles(static_cast<std::uint32_t>(mesh.triangles.size()));
  job.final_status.set_active_voxels(s.active_voxels());
  store_.WriteText(job.id, "status.pb", job.final_status.SerializeAsString());
}

void Aggregator::ExpireLeases(Job& job) {
  const auto now = Clock::now();
  for (auto it = job.leases.begin(); it != job.leases.end();) {
    if (it->second.first < now) {
      ++job.leases_expired;
      spdlog::warn("aggregate: job {}: {} of view {} not returned by {} in time; re-issued", job.id,
                   it->first.first == pb::STAGE_DEPTH ? "depth" : "propagate", it->first.second, it->second.second);
      it = job.leases.erase(it);
    } else {
      ++it;
    }
  }
}

pb::Envelope Aggregator::HandleTaskRequest(const pb::Envelope& req) {
  const pb::TaskRequest& tr = req.task_request();
  const int stage = tr.stage();
  if (stage != pb::STAGE_DEPTH && stage != pb::STAGE_PROPAGATE)
    return ErrorEnvelope(pb::ERROR_BAD_REQUEST, "unknown stage " + std::to_string(stage));
  for (auto& [id, jp] : jobs_) {
    Job& job = *jp;
    if (job.Ended() || !job.fusion) continue;
    ExpireLeases(job);
    for (int v = 0; v < job.n; ++v) {
      if (job.leases.count({stage, v})) continue;
      pb::Envelope out = NewEnvelope(id);
      pb::Task* task = out.mutable_task();
      if (stage == pb::STAGE_DEPTH) {
        if (job.sparse_ok[v] || !job.FramesOk(v, job.near.Neighbors(v))) continue;
        task->add_frames(v);
        for (int j : job.near.Neighbors(v)) task->add_frames(j);
      } else {
        if (job.dense_ok[v] || !job.sparse_ok[v]) continue;
        bool ready = true;
        for (int j : job.wide.Neighbors(v)) ready = ready && job.sparse_ok[j];
        if (!ready) continue;
        task->add_frames(v);
        if (job.geo.options.densify) {
          if (!job.FramesOk(v, job.photo.Neighbors(v))) continue;
          for (int j : job.photo.Neighbors(v)) task->add_frames(j);
        }
        for (int j : job.wide.Neighbors(v)) task->add_voters(j);
      }
      task->set_stage(static_cast<pb::Stage>(stage));
      task->set_view(v);
      task->set_lease_ms(options_.lease_ms);
      job.leases[{stage, v}] = {Clock::now() + std::chrono::milliseconds(options_.lease_ms), tr.worker()};
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
  if (job.Ended() || !job.fusion) {  // cancelled or failed meanwhile: nothing to do
    pb::Envelope ack = NewEnvelope(job.id);
    ack.mutable_ack();
    return ack;
  }
  if (v < 0 || v >= job.n) return ErrorEnvelope(pb::ERROR_BAD_REQUEST, "view " + std::to_string(v) + " out of range", job.id);
  if (r.stage() != pb::STAGE_DEPTH && r.stage() != pb::STAGE_PROPAGATE)
    return ErrorEnvelope(pb::ERROR_BAD_REQUEST, "unknown stage", job.id);
  job.leases.erase({static_cast<int>(r.stage()), v});
  if (!r.error().empty()) {
    EndJob(job, pb::STATE_FAILED, "view " + std::to_string(v) + ": " + r.error());
    pb::Envelope ack = NewEnvelope(job.id);
    ack.mutable_ack();
    return ack;
  }
  const std::string what = "task result of view " + std::to_string(v) + " from " + r.worker();
  DepthMap map;
  try {
    map = DepthMapFromProto(r.map(), job.geo.views[v].width, job.geo.views[v].height, what);
  } catch (const InputError& e) {
    return ErrorEnvelope(pb::ERROR_BAD_REQUEST, e.what(), job.id);
  }
  if (r.stage() == pb::STAGE_DEPTH) {
    if (r.map().kind() != pb::MAP_SPARSE) return ErrorEnvelope(pb::ERROR_BAD_REQUEST, what + ": not a sparse map", job.id);
    if (!job.sparse_ok[v]) {
      store_.WriteMap(job.id, r.map());
      job.sparse_ok[v] = 1;
      ++job.sparse_done;
    }
  } else {
    if (r.map().kind() != pb::MAP_DENSE && r.map().kind() != pb::MAP_FILTERED)
      return ErrorEnvelope(pb::ERROR_BAD_REQUEST, what + ": not a dense map", job.id);
    if (!job.dense_ok[v]) {
      pb::DepthMap stored = r.map();
      stored.set_kind(pb::MAP_DENSE);  // the map that is fused, whatever the stage made
      store_.WriteMap(job.id, stored);
      Integrate(job, v, map, true);
      MaybeFinish(job);
    }
  }
  pb::Envelope ack = NewEnvelope(job.id);
  ack.mutable_ack();
  return ack;
}

Aggregator::Deferred Aggregator::RefinedExport(const Job& job) const {
  RefineSnapshot snap;
  snap.id = job.id;
  snap.complete = job.state == pb::STATE_DONE;
  if (!snap.complete) {
    snap.geo = job.geo;
    snap.fused = job.fused;
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

pb::Envelope Aggregator::HandleExport(Job& job, const pb::ExportRequest& req, Deferred* deferred) {
  if (req.refine()) {
    if (job.state != pb::STATE_DONE && !job.fusion)
      return ErrorEnvelope(pb::ERROR_BAD_REQUEST,
                           "job " + job.id + " is " + pb::JobState_Name(job.state) + ": nothing to export", job.id);
    Deferred work = RefinedExport(job);
    if (!deferred) return work();
    *deferred = std::move(work);
    return pb::Envelope();
  }
  pb::Envelope out = NewEnvelope(job.id);
  pb::ExportReply* rep = out.mutable_export_reply();
  const fs::path dir = store_.JobDir(job.id);
  if (job.state == pb::STATE_DONE) {
    const TriangleMesh mesh = ReadPly(dir / "mesh.ply");
    rep->set_ply(ReadFileBytes(dir / "mesh.ply"));
    rep->set_vertices(mesh.vertices.size());
    rep->set_triangles(mesh.triangles.size());
    rep->set_views_fused(job.final_status.views_fused());
    rep->set_complete(true);
    return out;
  }
  if (!job.fusion) return ErrorEnvelope(pb::ERROR_BAD_REQUEST, "job " + job.id + " is " + pb::JobState_Name(job.state) +
                                                                   ": nothing to export", job.id);
  const TriangleMesh mesh = CurrentMesh(job, true);
  const fs::path tmp = dir / ("export_" + std::to_string(::getpid()) + ".ply");
  WritePly(mesh, tmp);
  rep->set_ply(ReadFileBytes(tmp));
  fs::remove(tmp);
  rep->set_vertices(mesh.vertices.size());
  rep->set_triangles(mesh.triangles.size());
  rep->set_views_fused(job.views_fused);
  rep->set_complete(false);
  return out;
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
        return ack;  // FindJob loaded it
      case pb::Envelope::kFrameSpooled: {
        const int k = static_cast<int>(req.frame_spooled().index());
        if (job->Ended() || !job->fusion) return ack;
        if (k < 0 || k >= job->n) return ErrorEnvelope(pb::ERROR_BAD_REQUEST, "frame " + std::to_string(k) + " out of range", job->id);
        if (!store_.HasFrame(job->id, k))
          return ErrorEnvelope(pb::ERROR_BAD_REQUEST, "frame " + std::to_string(k) + " is not in the job store", job->id);
        if (!job->frame_ok[k]) job->frame_ok[k] = 1, ++job->frames_spooled;  // duplicates are no-ops
        return ack;
      }
      case pb::Envelope::kIngestDone:
        if (job->Ended() || !job->fusion) return ack;
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
  RouterServer server(context, options_.endpoint, options_.max_message_bytes);
  spdlog::info("aggregate: serving on {} (store {}, lease {} ms)", options_.endpoint, store_.root().string(),
               options_.lease_ms);
  // Refined exports: run one at a time on another thread, in arrival order;
  // each is answered when its work is done.
  struct Pending {
    RouterServer::Incoming in;
    Deferred work;
  };
  std::deque<Pending> pending;
  std::future<pb::Envelope> running;
  auto reap = [&](bool wait) {
    if (!running.valid()) return;
    if (!wait && running.wait_for(std::chrono::seconds(0)) != std::future_status::ready) return;
    server.Reply(pending.front().in, running.get());
    pending.pop_front();
  };
  while (!StopRequested()) {
    reap(false);
    if (!running.valid() && !pending.empty()) running = std::async(std::launch::async, pending.front().work);
    auto in = server.Receive(std::chrono::milliseconds(pending.empty() ? 200 : 20));
    if (!in) continue;
    pb::Envelope reply;
    if (!in->ok) {
      spdlog::warn("aggregate: refused a message of {} bytes: {}", in->bytes, in->error.message());
      reply = NewEnvelope();
      *reply.mutable_error() = in->error;
    } else {
      Deferred work;
      reply = Handle(in->envelope, &work);
      if (work) {
        pending.push_back({std::move(*in), std::move(work)});
        continue;
      }
    }
    server.Reply(*in, reply);
  }
  reap(true);  // a refined export under way stops at its next view (or finishes refining) and is answered
  for (Pending& p : pending)
    server.Reply(p.in, ErrorEnvelope(pb::ERROR_INTERNAL, "lfrecon-aggregate stopped", p.in.envelope.job_id()));
  spdlog::info("aggregate: stopped");
}

}  // namespace lfrecon::svc
