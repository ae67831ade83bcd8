#pragma once
// Inside lfrecon-aggregate (not a public header): a job's state, shared by the
// files of the daemon, each with one job:
//   aggregator.cc  dispatch: requests to their handlers, the serving loop, the exports' lanes
//   leases.cc      view tasks: what is ready (the job plan's), leases, results, failures
//   job_fusion.cc  a job's fusion and checkpoint: loading (and replaying) it, the fusion thread, its end
//   export.cc      meshes on request: plain (of the live grid) and refined (from the checkpoint)
//   stream_plan.cc an open stream's growing plan: its new frames, its end, its failure at ingest
#include <atomic>
#include <condition_variable>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "aggregator.h"
#include "common/stored_depth.h"
#include "fusion/probabilistic_fusion.h"

namespace lfrecon::svc {

struct Aggregator::Job {
  std::string id;
  pb::JobState state = pb::STATE_INGESTING;
  std::string message;
  Clock::time_point created = Clock::now();
  pb::JobStatus final_status;  // for jobs that ended (loaded from status.pb)
  // Running jobs only. The serving thread's:
  bool active = false;  // running: the fusion thread is up, results are taken
  // Constant once loaded; for an open stream (geo.open) replaced as its frames
  // arrive (SetGeometry, stream_plan.cc). Other threads read shared_geo.
  JobGeometry geo;
  int n = 0;         // frames (views) of the job: of an open stream, those received so far
  int num_fused = 0;  // views to fuse: the plan's selected views (geo.plan.views); of an open stream, so far
  // Views whose depth (settled_depth) and propagate (settled) tasks may be leased:
  // every view once all cameras are known; of an open stream, those whose plan
  // entries are the whole stream's (ReconstructionPlan::SettledDepthFrames, SettledFrames).
  int settled = 0, settled_depth = 0;
  std::vector<char> frame_ok, sparse_ok, dense_ok;
  int frames_spooled = 0, sparse_done = 0, dense_done = 0;  // dense_done: maps received (stored)
  bool ingest_done = false;
  struct Lease {
    Clock::time_point deadline;
    WorkerId worker;
  };
  std::map<std::pair<int, int>, Lease> leases;  // (stage, view) -> its lease
  int leases_expired = 0;
  std::map<std::pair<int, int>, std::set<std::string>> leased_to;  // (stage, view) -> every worker (id) given it
  struct Tries {
    int failures = 0;
    std::set<std::string> failed_on;  // workers (ids) it failed on
  };
  std::map<std::pair<int, int>, Tries> tries;
  int tasks_failed = 0;
  Clock::time_point last_ingest = Clock::now();  // JobCreated, FrameSpooled, IngestDone (or the load)
  // Shared with the job's fusion thread and the exports:
  std::mutex geo_mu;                              // guards shared_geo
  std::shared_ptr<const JobGeometry> shared_geo;  // geo as the other threads take it (Geometry())
  std::mutex grid_mu;  // held while a view is integrated and while an export extracts its mesh
  std::unique_ptr<ProbabilisticFusion> fusion;  // guarded by grid_mu; released when the thread stops
  std::mutex queue_mu;                          // guards queue, fused (and stop's changes, for the wait)
  std::condition_variable queue_cv;
  // (view, append to fused.log): stored dense maps to fuse, in arrival order;
  // with the geometric consistency check they are fused in the plan's order
  // instead, each once its neighbours' maps are stored (ConsistencyNeighbours).
  std::deque<std::pair<int, bool>> queue;
  std::atomic<bool> stop{false};
  std::vector<char> fused;
  std::vector<char> stored;  // views whose dense map is in the store (Enqueue; cleared when found unreadable)
  std::vector<int> unreadable;  // stored dense maps the fusion thread could not read: done again
  std::atomic<int> views_fused{0};  // changes under grid_mu (with the grid)
  std::atomic<int> masked_views{0};  // of those, fused with their frame's mask as free space
  // Geometric consistency: foreground depths checked (not the views' own) and dropped, of the views fused.
  std::atomic<long long> geometric_checked{0}, geometric_dropped{0};
  std::atomic<std::uint64_t> active_voxels{0};
  enum Outcome { kFusing = 0, kFinished = 1, kFailed = 2 };
  std::atomic<int> outcome{kFusing};  // kFinished: every view fused, outputs written
  std::string fusion_error;           // kFailed: why (written before outcome)
  std::uint32_t triangles = 0;        // kFinished: of mesh.ply (written before outcome)
  double seconds_outputs = 0;
  int replay = 0;  // views queued from the checkpoint when loaded
  std::thread thread;

  ~Job() { StopFusion(*this, true); }
  // Serving thread: the job's geometry (loaded, or an open stream's grown or
  // ended): what is leased and fused follows its plan from now on.
  void SetGeometry(JobGeometry g) {
    geo = std::move(g);
    n = static_cast<int>(geo.views.size());
    num_fused = static_cast<int>(geo.plan.views.size());
    settled = ReconstructionPlan::SettledFrames(n, !geo.open, geo.options);
    settled_depth = ReconstructionPlan::SettledDepthFrames(n, !geo.open, geo.options);
    const auto size = static_cast<std::size_t>(n);
    frame_ok.resize(size, 0), sparse_ok.resize(size, 0), dense_ok.resize(size, 0);
    {
      std::lock_guard<std::mutex> lk(geo_mu);
      shared_geo = std::make_shared<const JobGeometry>(geo);
    }
    {
      std::lock_guard<std::mutex> lk(queue_mu);
      fused.resize(size, 0);
      stored.resize(size, 0);
    }
    queue_cv.notify_all();  // an ended stream may have every view fused already
  }
  // Any thread: the geometry as it is now (a view queued for fusion is in it).
  std::shared_ptr<const JobGeometry> Geometry() {
    std::lock_guard<std::mutex> lk(geo_mu);
    return shared_geo;
  }
  // Every view of the plan is fused, and the plan is final (the stream, if any, has ended).
  bool AllFused() {
    const std::shared_ptr<const JobGeometry> g = Geometry();
    return g && !g->open && views_fused >= static_cast<int>(g->plan.views.size());
  }
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

// The job's fusion grid, empty: V, voxel and σ_s as the plan sets them (as the embedded pipeline's).
std::unique_ptr<ProbabilisticFusion> NewFusion(const JobGeometry& geo);
// What the fusion integrates for view `v`, as `lfrecon run` does (EmbeddedPipeline):
// its stored dense map `dense` with the background floor (gated by the view's
// sparse map, read here) and then, unless the job's options turn it off, the
// free space outside its frame's mask when the frame carries one (Frame.mask,
// WithMaskFreeSpace; the frame's file is not read when no frame of the job
// carries a mask, JobGeometry::frame_masks). `masked` (may be null): whether a
// mask was applied.
// Throws InputError naming the frame's file when its mask is unreadable.
DepthMap FusionInput(const JobStore& store, const JobGeometry& geo, int v, DepthMap dense, bool* masked);
// The fused mesh with colour from the plan's colour frames (as the embedded
// pipeline's), those of `frame_ok` read from the store.
void ColourMesh(const JobStore& store, const JobGeometry& geo, const std::vector<char>& frame_ok, TriangleMesh* mesh);

}  // namespace lfrecon::svc
