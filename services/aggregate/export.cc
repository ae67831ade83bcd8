// lfrecon-aggregate, meshes on request: a plain export (the live grid's
// iso-surface, coloured) and a refined one (the grid rebuilt from the
// checkpoint, then FinishSurface as `lfrecon run`), both off the serving thread.
#include "aggregator_job.h"

#include <spdlog/spdlog.h>
#include <unistd.h>

#include <functional>
#include <sstream>

#include "fusion/mesh_coloring.h"
#include "io/ply.h"
#include "pipeline/finish_surface.h"
#include "util/error.h"
#include "util/progress.h"

namespace lfrecon::svc {
namespace fs = std::filesystem;

namespace {

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

// The object masks of the frames LoadColorViews gives for `ids`, in its order
// (an empty Mat where a frame has none), for CarvingOptions::carve_outside_masks.
std::vector<cv::Mat> LoadMasks(const JobStore& store, const JobGeometry& geo, const std::vector<int>& ids,
                               const std::vector<char>& frame_ok) {
  std::vector<cv::Mat> out;
  for (int v : ids)
    if (frame_ok[v]) out.push_back(geo.frame_masks ? store.ReadMask(geo.id, v, geo.views[v]) : cv::Mat());
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
// after fusion (FinishSurface, libs/pipeline/finish_surface.h): refinement with
// the plan's carving frames (and their masks when the job carves outside them,
// JobOptions.mask_carving), the fused iso-surface where it made nothing,
// colour from the plan's colour frames.
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
  StoredDepthCache depths(store, snap.id, StoredDepthCache::CapacityFor(po.geometric_consistency));
  int fused = 0;
  for (int v = 0; v < n; ++v) {
    if (!snap.fused[v]) continue;
    if (StopRequested()) throw std::runtime_error("lfrecon-aggregate is stopping");
    // As the job's fusion integrated it (geometric consistency, background floor, the mask's free space), as
    // lfrecon run does.
    cv::Mat own;
    DepthMap dense = store.ReadMap(snap.id, pb::MAP_DENSE, v, geo.views[v], &own);
    CheckStoredDenseMap(geo, v, own, &depths, &dense, nullptr);
    fusion->Integrate(geo.views[v], FusionInput(store, geo, v, std::move(dense), nullptr), v);
    ++fused;
  }
  const double seconds_fusion = tf.Seconds();
  TriangleMesh mesh;
  RefineStats rs;
  if (fused > 0) {
    // The plan's carving and colour frames, then what lfrecon run does after fusion (FinishSurface).
    std::map<int, cv::Mat> frames;
    const std::vector<ColorView> carve = LoadColorViews(store, geo, geo.plan.carving_frames, snap.frame_ok, &frames);
    const std::vector<ColorView> color = LoadColorViews(store, geo, geo.plan.color_frames, snap.frame_ok, &frames);
    const std::vector<cv::Mat> carve_masks =
        CarvesOutsideMasks(po) ? LoadMasks(store, geo, geo.plan.carving_frames, snap.frame_ok) : std::vector<cv::Mat>();
    FinishedSurface finished = FinishSurface(*fusion, fusion->ExtractMesh(po.meshing), carve, color, po, carve_masks);
    rs = finished.refine;
    mesh = std::move(finished.mesh);
  }
  fusion.reset();
  const fs::path tmp = dir / ("export_refined_" + std::to_string(::getpid()) + ".ply");
  WritePly(mesh, tmp);
  rep->set_ply(ReadFileBytes(tmp));
  if (snap.complete) CommitFile(tmp, cached);  // atomic and durable: a reader sees all of it or nothing
  else fs::remove(tmp);
  rep->set_vertices(mesh.vertices.size());
  rep->set_triangles(mesh.triangles.size());
  rep->set_views_fused(fused);
  spdlog::info("aggregate: job {}: refined export of {} fused views: {} triangles from {} carving views ({} carved, "
               "{} of them outside {} masks), {:.1f} s ({:.1f} re-fusing the checkpoint, {:.1f} refining)",
               snap.id, fused, mesh.triangles.size(), rs.carving_views, rs.carved, rs.carved_outside_masks,
               rs.mask_views, total.Seconds(), seconds_fusion, rs.seconds_total);
  return out;
}

}  // namespace

void ColourMesh(const JobStore& store, const JobGeometry& geo, const std::vector<char>& frame_ok, TriangleMesh* mesh) {
  const PipelineOptions& po = geo.options;
  if (geo.plan.color_frames.empty() || mesh->triangles.empty()) return;
  std::map<int, cv::Mat> frames;
  const std::vector<ColorView> cviews = LoadColorViews(store, geo, geo.plan.color_frames, frame_ok, &frames);
  if (!cviews.empty()) ColorizeMesh(mesh, cviews, po.coloring);
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
  // The geometry of now: an open stream's colour frames are its prefix's, as its frame_ok.
  std::shared_ptr<const JobGeometry> geo = job.Geometry();
  if (!geo) geo = std::make_shared<const JobGeometry>();  // a job loaded after its end (its mesh.ply is served)
  return [store = store_, job = &job, done, views_fused = job.final_status.views_fused(), geo,
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
          mesh = job->fusion->ExtractMesh(geo->options.meshing);
          views_fused = job->views_fused;
          complete = job->outcome == Job::kFinished;
        }
      }
      if (complete && mesh.triangles.empty() && fs::exists(dir / "mesh.ply")) {
        mesh = ReadPly(dir / "mesh.ply");
        rep->set_ply(ReadFileBytes(dir / "mesh.ply"));
      } else {
        ColourMesh(store, *geo, frame_ok, &mesh);
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

}  // namespace lfrecon::svc
