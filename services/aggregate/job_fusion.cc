// lfrecon-aggregate, a job's fusion and checkpoint: loading a job from the
// store (what a crash left, replaying fused.log), its fusion thread (dense
// maps into the grid in the plan's order, each once its geometric consistency
// neighbours' maps are stored, as lfrecon run; in arrival order without the
// check; the outputs when the last view is fused), its end and status.
#include "aggregator_job.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <iterator>
#include <sstream>

#include "io/ply.h"
#include "fusion/free_space.h"
#include "pipeline/embedded_pipeline.h"
#include "util/error.h"
#include "util/progress.h"

namespace lfrecon::svc {
namespace fs = std::filesystem;

// The job's fusion grid, empty: V, voxel and σ_s as the plan sets them (as the embedded pipeline's).
std::unique_ptr<ProbabilisticFusion> NewFusion(const JobGeometry& geo) {
  return std::make_unique<ProbabilisticFusion>(geo.plan.fusion);
}

DepthMap FusionInput(const JobStore& store, const JobGeometry& geo, int v, DepthMap dense, bool* masked) {
  const PipelineOptions& po = geo.options;
  const PinholeView& view = geo.views[static_cast<std::size_t>(v)];
  if (masked) *masked = false;
  if (NeedsBackgroundFloor(po)) {  // as lfrecon run: the same function on the same maps
    DepthMap sparse;
    try {
      sparse = store.ReadMap(geo.id, pb::MAP_SPARSE, v, view);
    } catch (const InputError& e) {  // the floor is then gated by the dense map alone
      spdlog::warn("aggregate: job {}: sparse map of view {} unreadable ({}): background floor gated without it",
                   geo.id, v, e.what());
    }
    dense = WithBackgroundFloor(dense, sparse, view, geo.volume, po);
  }
  const PipelineOptions::MaskFreeSpace& mf = po.mask_free_space;
  // After the floor, as lfrecon run. A job whose frames carry no mask reads no frame file here.
  if (mf.confidence > 0 && geo.frame_masks) {
    const cv::Mat mask = store.ReadMask(geo.id, v, view);
    if (!mask.empty()) {
      dense = WithMaskFreeSpace(dense, mask, mf.confidence, mf.margin_px);
      if (masked) *masked = true;
    }
  }
  return dense;
}

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
  // An open stream that gives V: its frames so far, and the plan grows with them (stream_plan.cc).
  job->SetGeometry(LoadJobGeometry(store_, id));
  const int n = job->n;
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
      // Frames are compact (encoded images, common/job_store.h): any length may be whole; one that
      // does not decode fails its tasks, which name the file.
      if (intact(store_.FramePath(id, k), 1)) job->frame_ok[k] = 1, ++job->frames_spooled;
      else if (bad_frame < 0) bad_frame = k;
    }
    if (store_.HasMap(id, pb::MAP_SPARSE, k) && intact(store_.MapPath(id, pb::MAP_SPARSE, k), pixels * 4))
      job->sparse_ok[k] = 1, ++job->sparse_done;
    if (store_.HasMap(id, pb::MAP_DENSE, k)) intact(store_.MapPath(id, pb::MAP_DENSE, k), pixels * 4);
  }
  job->ingest_done = !job->geo.open && store_.ReadText(id, "ingest.done").has_value();
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

// Serving thread: the dense map of `view` is in the store; it is fused after those queued before it.
void Aggregator::Enqueue(Job& job, int view, bool log) const {
  if (!job.dense_ok[view]) job.dense_ok[view] = 1, ++job.dense_done;
  {
    std::lock_guard<std::mutex> lk(job.queue_mu);
    job.queue.emplace_back(view, log);
    job.stored[view] = 1;
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
  // The geometry as this thread last took it: an open stream's grows (a view
  // queued for fusion is in every one taken after); the options are the same in all.
  std::shared_ptr<const JobGeometry> geo = job.Geometry();
  const PipelineOptions po = geo->options;
  // Geometric consistency: the neighbours' depths, read once for the views that share them.
  const bool checked = po.densify && po.geometric_consistency.Delay() > 0;
  StoredDepthCache depths(store_, id, StoredDepthCache::CapacityFor(po.geometric_consistency));
  Timer replay_timer;
  int done = 0;
  try {
    for (;;) {
      std::pair<int, bool> item{-1, false};
      {
        std::unique_lock<std::mutex> lk(job.queue_mu);
        // The next map to fuse: the first queued (arrival order, or fused.log's
        // when replaying); with the geometric consistency check, the first
        // unfused view of the plan's order (as lfrecon run fuses them), once
        // its map and its neighbours' are stored.
        auto take_ready = [&]() {
          geo = job.Geometry();
          for (auto it = job.queue.begin(); it != job.queue.end();)
            it = job.fused[it->first] ? job.queue.erase(it) : std::next(it);
          auto pick = job.queue.begin();
          if (checked && pick != job.queue.end()) {
            const std::vector<int>& order = geo->plan.order;
            const auto next = std::find_if(order.begin(), order.end(), [&](int v) { return !job.fused[v]; });
            if (next == order.end()) return false;
            pick = std::find_if(job.queue.begin(), job.queue.end(), [&](const auto& e) { return e.first == *next; });
            if (pick == job.queue.end()) return false;
            bool complete = true;
            for (int w : ConsistencyNeighbours(*geo, *next, &complete))
              if (!job.stored[w]) return false;
            if (!complete) return false;
          }
          if (pick == job.queue.end()) return false;
          item = *pick;
          job.queue.erase(pick);
          return true;
        };
        // A signal cannot notify: look at StopRequested() now and then. With
        // nothing queued, an ended stream's last views may all be fused already.
        while (!job.stop && !StopRequested() &&
               (job.outcome != Job::kFusing || (!take_ready() && !job.AllFused())))
          job.queue_cv.wait_for(lk, std::chrono::milliseconds(200));
        if (job.stop || StopRequested()) break;
      }
      geo = job.Geometry();
      if (item.first >= 0) {  // a stored dense map: into the grid
        const int v = item.first;
        DepthMap map;
        cv::Mat own;
        // A map the store lost (a crash): the view is done again (and a view whose neighbour it is waits for it).
        auto lost = [&](int w, const std::exception& e) {
          spdlog::warn("aggregate: job {}: stored dense map of view {} unreadable ({}): removed, re-issued", id, w,
                       e.what());
          std::error_code ec;
          fs::remove(store_.MapPath(id, pb::MAP_DENSE, w), ec);
          depths.Forget(w);
          std::lock_guard<std::mutex> lk(job.queue_mu);
          job.unreadable.push_back(w);
          job.stored[w] = 0;
        };
        try {
          map = store_.ReadMap(id, pb::MAP_DENSE, v, geo->views[v], &own);
        } catch (const InputError& e) {
          lost(v, e);
          continue;
        }
        int unreadable = -1;
        try {
          const GeometricConsistencyStats gs = CheckStoredDenseMap(*geo, v, own, &depths, &map, &unreadable);
          job.geometric_checked += gs.foreground - gs.own;
          job.geometric_dropped += gs.dropped;
        } catch (const InputError& e) {
          if (unreadable < 0) throw;
          lost(unreadable, e);
          std::lock_guard<std::mutex> lk(job.queue_mu);
          job.queue.push_front(item);  // fused when the neighbour's map is stored again
          continue;
        }
        bool masked = false;
        map = FusionInput(store_, *geo, v, std::move(map), &masked);
        {
          std::lock_guard<std::mutex> grid(job.grid_mu);
          job.fusion->Integrate(geo->views[v], map, v);
          for (int slept = 0; slept < options_.fusion_delay_ms && !job.stop && !StopRequested(); slept += 10)
            std::this_thread::sleep_for(std::chrono::milliseconds(10));  // fault injection (tests)
          job.active_voxels = job.fusion->Stats().active_voxels;
          if (item.second) store_.AppendLine(id, "fused.log", std::to_string(v));  // before anyone sees it fused
          {
            std::lock_guard<std::mutex> lk(job.queue_mu);
            job.fused[v] = 1;
          }
          ++job.views_fused;
          if (masked) ++job.masked_views;
        }
        if (++done == job.replay && job.replay > 0)
          spdlog::info("aggregate: job {}: {} views replayed from the checkpoint in {:.1f} s", id, job.replay,
                       replay_timer.Seconds());
        if (!job.AllFused()) continue;
      }
      // Every view fused (of a stream: of its whole plan, after its end): the job's
      // outputs. The grid is complete and no other thread changes it, so exports
      // may read it meanwhile.
      geo = job.Geometry();
      Timer t;
      const fs::path dir = store_.JobDir(id);
      const int n = static_cast<int>(geo->views.size());
      std::vector<char> frame_ok(n, 0);
      for (int k = 0; k < n; ++k) frame_ok[k] = store_.HasFrame(id, k);
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
      ColourMesh(store_, *geo, frame_ok, &mesh);
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
    spdlog::info("aggregate: job {}: {} views fused ({} with their mask's free space; geometric consistency dropped "
                 "{} of {} checked foreground depths), mesh {} triangles ({:.1f} s)",
                 job.id, job.views_fused.load(), job.masked_views.load(), job.geometric_dropped.load(),
                 job.geometric_checked.load(), job.triangles, job.seconds_outputs);
    EndJob(job, pb::STATE_DONE, "");
  }
}

pb::JobStatus Aggregator::Status(const Job& job) const {
  if (!job.active && job.final_status.state() != pb::STATE_UNKNOWN) return job.final_status;
  pb::JobStatus s;
  s.set_state(job.state);
  s.set_num_views(job.num_fused);  // the views fused when it is done (the plan's selection)
  s.set_frames_spooled(job.frames_spooled);
  s.set_sparse_done(job.sparse_done);
  s.set_dense_done(job.dense_done);
  s.set_views_fused(job.views_fused);
  s.set_message(job.message);
  if (job.geo.open && job.message.empty())
    s.set_message("stream open: " + std::to_string(job.n) + " frames received; the views before frame " +
                  std::to_string(job.settled) + " are settled and processed now, the rest after its end");
  s.set_seconds(std::chrono::duration<double>(Clock::now() - job.created).count());
  s.set_active_voxels(static_cast<std::uint32_t>(job.active_voxels));
  s.set_leases_expired(job.leases_expired);
  s.set_tasks_failed(job.tasks_failed);
  s.set_masked_views(static_cast<std::uint32_t>(job.masked_views));
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

}  // namespace lfrecon::svc
