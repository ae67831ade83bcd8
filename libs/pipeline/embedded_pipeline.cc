#include "pipeline/embedded_pipeline.h"

#include <spdlog/spdlog.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <tbb/task_group.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <map>
#include <set>

#include "fusion/free_space.h"
#include "fusion/geometric_consistency.h"
#include "fusion/mesh_render.h"
#include "pipeline/finish_surface.h"
#include "pipeline/reconstruction_plan.h"
#include "propagation/edge_preview.h"
#include "io/depth_map_io.h"
#include "io/ply.h"
#include "util/error.h"
#include "util/memory.h"
#include "util/progress.h"

namespace lfrecon {
namespace fs = std::filesystem;

bool NeedsBackgroundFloor(const PipelineOptions& options) {
  return options.densify && options.background_floor.floor > 0;
}

DepthMap WithBackgroundFloor(const DepthMap& dense, const DepthMap& sparse, const PinholeView& view,
                             const BoundingBox& volume, const PipelineOptions& options) {
  if (!NeedsBackgroundFloor(options)) return dense;
  const PipelineOptions::BackgroundFloor& bf = options.background_floor;
  cv::Mat protect;  // sparse depths inside V: a thin part this view's dense map may have lost
  if (bf.gate_on_sparse && sparse.depth.size() == dense.depth.size())
    protect = DepthPropagator::LabelFromVolume(view, sparse, volume).label ==
              static_cast<std::uint8_t>(DepthLabel::kForeground);
  return WithGatedBackgroundFloor(dense, view, volume, bf.floor, bf.gate_px, protect);
}

EmbeddedPipeline::EmbeddedPipeline(std::vector<PinholeView> views, const BoundingBox& volume,
                                   const PipelineOptions& options, std::vector<std::string> names)
    : views_(std::move(views)), volume_(volume), options_(options), names_(std::move(names)) {
  options_.Check();
  if (!volume_.IsValid()) throw OptionError("the volume V is empty or not finite");
  if (!names_.empty() && names_.size() != views_.size())
    throw OptionError("pipeline: " + std::to_string(names_.size()) + " names for " + std::to_string(views_.size()) +
                      " views");
}

namespace {

std::string DefaultStem(int i) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%05d", i);
  return buf;
}

nlohmann::json BoxJson(const BoundingBox& b) {
  return {{"min", {b.min.x(), b.min.y(), b.min.z()}}, {"max", {b.max.x(), b.max.y(), b.max.z()}}};
}


// A frame of the densification window.
struct WindowFrame {
  ViewImage tapped;          // as tapped, when the frame is not 8-bit (shares the depth stage's pixels)
  cv::Mat pixels;            // CV_8UC3 otherwise, and `tapped` holds only the view
  bool depth_smoothed = false;  // the depth stage had filled `smoothed` (presmooth_sigma of §3.1)
};

// `compacted`: CompactFrame of the frame (the depth stage's copy, shared).
WindowFrame MakeWindowFrame(const ViewImage& v, const cv::Mat& compacted, bool compact) {
  WindowFrame w;
  w.tapped.view = v.view;
  w.tapped.on_grid = v.on_grid;
  const cv::Mat& c = compact ? compacted : v.image;
  if (c.depth() == CV_8U) {
    w.pixels = c;
    w.depth_smoothed = !v.smoothed.empty();
  } else {
    w.tapped = v;
  }
  return w;
}

// The ViewImage the photoconsistency reads, as it was before frames were held
// in 8 bits: `smoothed` as the depth stage filled it (its presmooth_sigma), or
// as the photoconsistency would make it (its own). For a neighbour
// (`keep_image` false) only `smoothed` is read when presmooth_sigma > 0, so
// `image` then shares it and the unsmoothed floats are not kept.
ViewImage MaterializeWindowFrame(const WindowFrame& w, const GradientDepthOptions& depth,
                                 const PhotoconsistencyOptions& photo, bool keep_image) {
  if (w.pixels.empty()) return w.tapped;
  ViewImage v;
  v.view = w.tapped.view;
  v.on_grid = w.tapped.on_grid;
  v.image = ExpandFrame(w.pixels);
  if (photo.presmooth_sigma <= 0) return v;
  if (w.depth_smoothed && depth.presmooth_sigma <= 0)
    v.smoothed = v.image;
  else
    cv::GaussianBlur(v.image, v.smoothed, cv::Size(0, 0),
                     w.depth_smoothed ? depth.presmooth_sigma : photo.presmooth_sigma);
  if (!keep_image) v.image = v.smoothed;
  return v;
}

// Whether BidirectionalPhotoconsistency::Compute would take the frame's
// ViewImage into account (a CV_32FC3 frame), without making it.
bool UsableWindowFrame(const WindowFrame& w) {
  return !w.pixels.empty() || (!w.tapped.image.empty() && w.tapped.image.type() == CV_32FC3);
}

// DepthPropagator::Run(reference, neighbours, filtered, volume).dense, bit for
// bit, with the photoconsistency fed one neighbour at a time: each neighbour's
// float frame (and pre-smoothed copy) is made, added and dropped before the
// next, so only one exists at once (§4.1 reads them together otherwise).
// `edge_classes` (if not null): the edges' classes (EdgeConsistency::Classify)
// for a preview; left empty when the input is not usable.
DepthMap DensifyNeighbourByNeighbour(const DepthPropagator& propagator, const ViewImage& reference,
                                     const std::vector<const WindowFrame*>& neighbours, const DepthMap& filtered,
                                     const BoundingBox& volume, const GradientDepthOptions& go,
                                     cv::Mat* edge_classes = nullptr) {
  const PropagationOptions& options = propagator.options();
  const int rows = reference.image.rows, cols = reference.image.cols;
  if (!DepthPropagator::ValidInput(reference, filtered)) return DepthMap(rows, cols);
  const DepthMap labelled = DepthPropagator::LabelFromVolume(reference.view, filtered, volume);
  // The neighbours in the order Compute adds them up.
  std::vector<const WindowFrame*> usable;
  std::vector<const PinholeView*> views;
  for (const WindowFrame* w : neighbours)
    if (w && UsableWindowFrame(*w)) {
      usable.push_back(w);
      views.push_back(&w->tapped.view);
    }
  // Neighbour k + 1's frame is made (one thread: expansion and pre-smoothing)
  // while neighbour k is added (every thread), in the same order.
  auto for_each_frame = [&](const std::vector<int>& order, const std::function<void(const ViewImage&)>& add) {
    auto make = [&](std::size_t k) {
      return MaterializeWindowFrame(*usable[static_cast<std::size_t>(order[k])], go, options.photo, false);
    };
    ViewImage next;
    if (!order.empty()) next = make(0);
    for (std::size_t k = 0; k < order.size(); ++k) {
      const ViewImage current = std::move(next);
      next = ViewImage();
      tbb::task_group making;
      if (k + 1 < order.size()) making.run([&, k] { next = make(k + 1); });
      try {
        add(current);
      } catch (...) {
        making.wait();
        throw;
      }
      making.wait();
    }
  };
  const BidirectionalPhotoconsistency photo(options.photo);
  PhotoconsistencyAccumulator acc(options.photo);
  acc.Begin(reference, labelled);
  for_each_frame(photo.SelectNeighbors(reference.view, views), [&](const ViewImage& v) { acc.Add(v); });
  const EdgeConsistency edges = acc.Finish();
  if (edge_classes) *edge_classes = edges.Classify(options.photo.silhouette_ratio);
  DepthMap dense = propagator.Filter(reference.image, propagator.Splat(labelled, edges));
  if (options.consistency.views > 0) {  // second pass, again one neighbour at a time
    DenseConsistencyAccumulator check(options.consistency);
    check.Begin(reference, dense, labelled.depth);
    for_each_frame(check.SelectNeighbors(reference.view, views), [&](const ViewImage& v) { check.Add(v); });
    ApplyDenseConsistency(check.Finish(), options.consistency.rho_min, &dense);
  }
  if (options.refinement.views > 0) {  // third pass, likewise
    PhotometricRefinementAccumulator refine(options.refinement);
    for_each_frame(refine.Begin(reference, dense, views, labelled.depth), [&](const ViewImage& v) { refine.Add(v); });
    refine.Finish(&dense);
  }
  return dense;
}

}  // namespace

PipelineResult EmbeddedPipeline::Run(FrameSource& frames) {
  Timer total;
  const int n = static_cast<int>(views_.size());
  if (frames.NumFrames() > 0 && frames.NumFrames() < n)
    throw InputError("frames", std::to_string(frames.NumFrames()) + " frames for " + std::to_string(n) + " views");
  // Which views, which neighbours, which frames for colour and carving: the plan, as the service computes it.
  const ReconstructionPlan plan = ReconstructionPlan::Compute(views_, volume_, options_);
  const std::vector<int>& wanted = plan.views;

  PipelineResult result;
  PipelineStats& st = result.stats;
  const FusionOptions& fo = plan.fusion;
  st.voxel_size = fo.voxel_size;
  const Eigen::Vector3i gs = fo.GridSize();
  ProbabilisticFusion fusion(fo);
  spdlog::info("run: {} of {} views, V {:.3f} x {:.3f} x {:.3f} m, voxel {:.2f} mm ({} x {} x {}), {}", wanted.size(),
               n, volume_.Extent().x(), volume_.Extent().y(), volume_.Extent().z(), 1000 * fo.voxel_size, gs.x(),
               gs.y(), gs.z(), options_.densify ? "dense depth (§4)" : "filtered sparse depth (no densification)");

  const bool write = !options_.out_dir.empty();
  if (write) fs::create_directories(options_.out_dir);
  if (write && options_.write_depth)
    for (const char* sub : {"depth", "confidence"}) fs::create_directories(options_.out_dir / sub);
  // Previews for report.html: a few views evenly spread over those processed.
  std::set<int> preview_ids;
  if (write && !wanted.empty())
    for (std::size_t k = 0, m = std::min<std::size_t>(options_.preview_views, wanted.size()); k < m; ++k)
      preview_ids.insert(wanted[k * wanted.size() / m]);
  if (!preview_ids.empty()) {
    fs::create_directories(options_.out_dir / "preview");
    if (options_.densify) fs::create_directories(options_.out_dir / "edges");
  }
  auto stem_of = [&](int i) { return names_.empty() ? DefaultStem(i) : fs::path(names_[i]).stem().string(); };

  // The densification window: frame j is kept while a view that needs it
  // (itself or a view within the photoconsistency angle) is still pending.
  std::vector<int> refcount(n, 0);
  if (options_.densify)
    for (int i : wanted) {
      ++refcount[i];
      for (int j : plan.PhotoNeighbours(i)) ++refcount[j];
    }
  std::map<int, WindowFrame> window;
  // Frames kept for colouring and for carving: a few evenly spread over the processed views (the plan's).
  const std::set<int> color_ids(plan.color_frames.begin(), plan.color_frames.end());
  const std::set<int> carve_ids(plan.carving_frames.begin(), plan.carving_frames.end());
  std::vector<ColorView> color_views, carve_views;
  std::map<int, cv::Mat> kept_frames;  // colour and carving frames (CompactFrame) until the stream ends

  StreamingDepth depth(views_, volume_, options_.depth);
  depth.SetFrameTap([&](int f, const ViewImage& v, const cv::Mat& compacted) {
    const bool compact = options_.compact_frames;
    if (refcount[f] > 0) window[f] = MakeWindowFrame(v, compacted, compact);
    st.max_frames_held_pipeline = std::max(st.max_frames_held_pipeline, static_cast<int>(window.size()));
    if (color_ids.count(f) || carve_ids.count(f)) kept_frames[f] = compact ? compacted : v.image;
  });

  const DepthPropagator propagator(options_.propagation);
  int done = 0;
  // Fusion of one view's dense map (after the geometric consistency check when on).
  auto fuse = [&](int i, const DepthMap& fused_map, const DepthMap& sparse) {
    st.fused_pixels += fused_map.CountValid();
    Timer t;
    // Free space added before fusion; each step returns the map as it is when it is off.
    DepthMap input = WithBackgroundFloor(fused_map, sparse, views_[i], volume_, options_);
    const PipelineOptions::MaskFreeSpace& mf = options_.mask_free_space;
    const cv::Mat mask = mask_of_view_ && mf.confidence > 0 ? mask_of_view_(i) : cv::Mat();
    if (!mask.empty()) {
      if (mask.size() != fused_map.depth.size())
        throw InputError("mask of view " + std::to_string(i), std::to_string(mask.cols) + "x" +
                         std::to_string(mask.rows) + ", its frame " + std::to_string(fused_map.depth.cols) + "x" +
                         std::to_string(fused_map.depth.rows));
      input = WithMaskFreeSpace(input, mask, mf.confidence, mf.margin_px);
      ++st.masked_views;
    }
    fusion.Integrate(views_[i], input, i);
    st.seconds_fusion += t.Seconds();
    st.cpu_fusion += t.CpuSeconds();
    if (write && options_.write_depth) {
      const std::string stem = stem_of(i);
      WritePfm(options_.out_dir / "depth" / (stem + ".pfm"), fused_map.depth);
      WritePfm(options_.out_dir / "confidence" / (stem + ".pfm"), fused_map.confidence);
    }
    ++done;
    if (view_callback_) view_callback_(i, done, static_cast<int>(wanted.size()));
  };
  // Multi-view geometric consistency (GeometricConsistencyOptions): each dense
  // map waits until the maps of its neighbours (positions ± the offsets in
  // plan.order, the order the depth stage completes the views in) are
  // densified, is checked against them unchecked, and is fused, in plan.order
  // (as the service's aggregator does).
  const GeometricConsistencyOptions& gc = options_.geometric_consistency;
  const int delay = options_.densify ? gc.Delay() : 0;
  const int num_wanted = static_cast<int>(plan.order.size());
  struct PendingView {
    int view;
    DepthMap dense;
    PackedDepthMap sparse;  // for the background floor's gate (empty when the floor is off)
    cv::Mat own;
  };
  std::map<int, PendingView> pending;  // by position in plan.order
  std::map<int, cv::Mat> unchecked;    // position -> unchecked dense depth, while a pending view needs it
  int next_fuse = 0;                   // position fused next
  auto ready = [&](int p) {
    for (int q : NeighbourPositions(p, num_wanted, gc))
      if (!unchecked.count(q)) return false;
    return true;
  };
  auto check_and_fuse = [&](PendingView pv, int p) {
    std::vector<NeighbourDepth> nbs;
    for (int q : NeighbourPositions(p, num_wanted, gc)) {
      const auto it = unchecked.find(q);
      if (it != unchecked.end()) nbs.push_back({&views_[plan.order[q]], &it->second});
    }
    Timer t;
    const GeometricConsistencyStats gs = ApplyGeometricConsistency(views_[pv.view], pv.own, nbs, volume_, gc, &pv.dense);
    st.geometric_checked += gs.foreground - gs.own;
    st.geometric_dropped += gs.dropped;
    st.seconds_fusion += t.Seconds();
    st.cpu_fusion += t.CpuSeconds();
    fuse(pv.view, pv.dense, pv.sparse.Unpack());
  };
  // Fuses the pending views from next_fuse on while their neighbours are there
  // (all of them at the end, `flush`: those missing were never densified).
  auto fuse_ready = [&](bool flush) {
    for (auto it = pending.begin(); it != pending.end() && (flush || (it->first == next_fuse && ready(next_fuse)));) {
      next_fuse = it->first + 1;
      check_and_fuse(std::move(it->second), it->first);
      it = pending.erase(it);
      // Maps no view after next_fuse looks back at.
      while (!unchecked.empty() && unchecked.begin()->first < next_fuse - delay) unchecked.erase(unchecked.begin());
    }
  };

  const StreamingDepthStats ds = depth.Run(
      frames, plan.depth, [&](int i, const cv::Mat& image, const DepthMap& sparse, const DepthMap& filtered) {
        const DepthMap& base = options_.depth.run_filter ? filtered : sparse;
        st.sparse_pixels += sparse.CountValid();
        st.filtered_pixels += filtered.CountValid();
        DepthMap fused_map;
        cv::Mat own;  // geometric consistency: where the dense depth is the view's own filtered depth
        const bool preview = preview_ids.count(i) > 0;
        if (options_.densify) {
          Timer t;
          // Float frames exist only while this view is densified, and of
          // its neighbours only one at a time.
          const GradientDepthOptions& go = options_.depth.gradient;
          const PhotoconsistencyOptions& po = options_.propagation.photo;
          std::vector<const WindowFrame*> nbs;
          nbs.reserve(plan.PhotoNeighbours(i).size());
          for (int j : plan.PhotoNeighbours(i)) {
            const auto it = window.find(j);
            if (it != window.end()) nbs.push_back(&it->second);
          }
          ViewImage reference;
          const auto ref = window.find(i);
          if (ref != window.end()) {
            reference = MaterializeWindowFrame(ref->second, go, po, true);
          } else {  // not expected: the tap precedes the sink
            reference.view = views_[i];
            reference.image = image;
          }
          cv::Mat edge_classes;
          fused_map = DensifyNeighbourByNeighbour(propagator, reference, nbs, base, volume_, go,
                                                  preview ? &edge_classes : nullptr);
          st.seconds_densify += t.Seconds();
          st.cpu_densify += t.CpuSeconds();
          if (delay > 0) own = OwnDepthMask(fused_map, base, gc.own_tolerance);
          if (preview && !edge_classes.empty())
            WriteEdgePreview(options_.out_dir / "edges" / (stem_of(i) + ".png"), reference.image, edge_classes);
          for (int j : plan.PhotoNeighbours(i))
            if (--refcount[j] == 0) window.erase(j);
          if (--refcount[i] == 0) window.erase(i);
        } else {
          // TODO(propagation): without densification the filtered sparse maps are fused as they are.
          fused_map = base;
        }
        if (preview && fused_map.CountValid() > 0)
          WriteDepthPreview(options_.out_dir / "preview" / (stem_of(i) + ".png"), fused_map.depth, image);
        if (delay == 0) {
          fuse(i, fused_map, sparse);
          return;
        }
        // Geometric consistency: the map waits for its neighbours' maps.
        const int p = plan.order_position[i];
        unchecked[p] = fused_map.depth.clone();
        pending[p] = {i, std::move(fused_map),
                      NeedsBackgroundFloor(options_) ? PackedDepthMap::Pack(sparse) : PackedDepthMap(), std::move(own)};
        fuse_ready(false);
      });
  fuse_ready(true);  // every view is densified: nothing is missing
  unchecked.clear();
  window.clear();
  // The carving frames' object masks (CarvingOptions::carve_outside_masks).
  const bool mask_carving = mask_of_view_ && CarvesOutsideMasks(options_);
  std::vector<cv::Mat> carve_masks;
  {
    std::map<int, cv::Mat> expanded;  // colour and carving frames share pixels
    for (auto& [f, pixels] : kept_frames) expanded[f] = ExpandFrame(pixels);
    kept_frames.clear();
    for (const auto& [f, image] : expanded) {
      if (color_ids.count(f)) color_views.push_back({views_[f], image, cv::Mat()});
      if (!carve_ids.count(f)) continue;
      carve_views.push_back({views_[f], image, cv::Mat()});
      if (!mask_carving) continue;
      cv::Mat mask = mask_of_view_(f);
      if (!mask.empty() && mask.size() != image.size())
        throw InputError("mask of view " + std::to_string(f), std::to_string(mask.cols) + "x" +
                         std::to_string(mask.rows) + ", its frame " + std::to_string(image.cols) + "x" +
                         std::to_string(image.rows));
      carve_masks.push_back(std::move(mask));
    }
  }
  if (delay > 0)
    spdlog::info("run: geometric consistency: {} of {} checked foreground depths dropped ({:.1f} %)",
                 st.geometric_dropped, st.geometric_checked,
                 100.0 * st.geometric_dropped / std::max<long long>(1, st.geometric_checked));
  st.views = done;
  st.frames_read = ds.frames_read;
  st.max_frames_held_depth = ds.max_frames_held;
  st.max_frames_pending_depth = ds.max_pending_frames;
  st.seconds_sparse = ds.seconds_sparse;
  st.seconds_filter = ds.seconds_filter;
  st.cpu_sparse = ds.cpu_seconds_sparse;
  st.cpu_filter = ds.cpu_seconds_filter;
  const FusionStats fs_stats = fusion.Stats();
  st.active_voxels = fs_stats.active_voxels;
  st.grid_bytes = fs_stats.grid_bytes;
  spdlog::info(
      "run: fused {} views ({:.1f} s depth, {:.1f} s densify, {:.1f} s fusion: {:.1f} activate, {:.1f} back-fill, "
      "{:.1f} update), {} active voxels, {:.0f} MiB grid + {:.0f} MiB stored maps",
      done, ds.seconds_sparse + ds.seconds_filter, st.seconds_densify, st.seconds_fusion, fs_stats.activate_s,
      fs_stats.backfill_s, fs_stats.update_s, fs_stats.active_voxels, fs_stats.grid_bytes / 1048576.0,
      fs_stats.store_bytes / 1048576.0);

  Timer tm;
  MeshingOptions mo = options_.meshing;
  const double iso = mo.threshold < 0 ? fo.surface_threshold : mo.threshold;
  fusion.ForEachVoxel([&](const Eigen::Vector3i&, double sum_log_p, int num_views) {
    if (num_views > 0 && std::exp(sum_log_p / num_views) >= iso) ++st.voxels_above_threshold;
  });
  result.mesh_raw = fusion.ExtractMesh(mo);
  st.seconds_mesh = tm.Seconds();
  st.cpu_mesh = tm.CpuSeconds();
  const Timer tf;
  st.carving_frames = static_cast<int>(carve_views.size());
  st.color_frames = static_cast<int>(color_views.size());
  // Refine, fall back to the fused surface, colour: as the service's refined export.
  FinishedSurface finished = FinishSurface(fusion, result.mesh_raw, carve_views, color_views, options_, carve_masks);
  carve_views.clear();
  carve_masks.clear();
  color_views.clear();
  result.mesh = std::move(finished.mesh);
  st.refine = finished.refine;
  st.seconds_refine = finished.seconds_refine;
  st.seconds_smooth = finished.seconds_smooth;
  st.rim_trim = finished.rim_trim;
  st.smoothing = finished.smoothing;
  st.seconds_color = finished.seconds_color;
  st.cpu_finish = tf.CpuSeconds();
  st.mesh_vertices = result.mesh.vertices.size();
  st.mesh_triangles = result.mesh.triangles.size();
  spdlog::info("run: {} of {} active voxels have H >= {}", st.voxels_above_threshold, st.active_voxels, iso);
  spdlog::info("run: mesh {} vertices, {} triangles ({:.1f} s), coloured from {} frames ({:.1f} s)",
               st.mesh_vertices, st.mesh_triangles, st.seconds_mesh, st.color_frames, st.seconds_color);

  Timer tw;
  if (write) {
    WritePly(result.mesh, options_.out_dir / "mesh.ply");
    WritePly(result.mesh_raw, options_.out_dir / "mesh_raw.ply");
    if (options_.write_vdb) fusion.WriteVdb(options_.out_dir / "grid.vdb");
    if (options_.write_turntable) {
      const fs::path png = options_.out_dir / "mesh_turntable.png";
      if (!cv::imwrite(png.string(), RenderTurntable(result.mesh, volume_)))
        throw InputError(png.string(), "cannot write the turntable render");
    }
  }
  st.seconds_write = tw.Seconds();
  st.cpu_write = tw.CpuSeconds();
  st.seconds_total = total.Seconds();
  st.cpu_total = total.CpuSeconds();
  st.peak_rss_bytes = PeakRssBytes();

  const auto& po = options_.propagation;
  result.report = {
      {"views", {{"total", n}, {"processed", st.views}, {"selected", plan.views.size()},
                 {"selection", options_.views.empty() && options_.selection.enabled
                                   ? nlohmann::json(options_.selection.min_step_deg)
                                   : nlohmann::json(options_.views.empty() ? "all" : "given")}}},
      {"volume", BoxJson(volume_)},
      {"voxel_size", st.voxel_size},
      {"grid_size", {gs.x(), gs.y(), gs.z()}},
      {"seconds",
       {{"depth_sparse", st.seconds_sparse},
        {"depth_filter", st.seconds_filter},
        {"densify", st.seconds_densify},
        {"fusion", st.seconds_fusion},
        {"fusion_activate", fs_stats.activate_s},
        {"fusion_backfill", fs_stats.backfill_s},
        {"fusion_update", fs_stats.update_s},
        {"mesh", st.seconds_mesh},
        {"refine", st.seconds_refine},
        {"refine_carving", st.refine.seconds_carving},
        {"refine_poisson", st.refine.seconds_poisson},
        {"smooth", st.seconds_smooth},
        {"color", st.seconds_color},
        {"write", st.seconds_write},
        {"total", st.seconds_total}}},
      // Process CPU (user + system, every thread) of the same stages; their
      // sum is below "total" by what runs outside them (reading, planning).
      {"cpu_seconds",
       {{"depth_sparse", st.cpu_sparse},
        {"depth_filter", st.cpu_filter},
        {"densify", st.cpu_densify},
        {"fusion", st.cpu_fusion},
        {"mesh", st.cpu_mesh},
        {"refine_and_color", st.cpu_finish},
        {"write", st.cpu_write},
        {"total", st.cpu_total}}},
      {"peak_rss_bytes", st.peak_rss_bytes},
      {"counts",
       {{"frames_read", st.frames_read},
        {"max_frames_held_depth", st.max_frames_held_depth},
        {"max_frames_held_pipeline", st.max_frames_held_pipeline},
        {"max_frames_pending_depth", st.max_frames_pending_depth},
        {"color_frames", st.color_frames},
        {"masked_views", st.masked_views},
        {"sparse_pixels", st.sparse_pixels},
        {"filtered_pixels", st.filtered_pixels},
        {"fused_pixels", st.fused_pixels},
        {"geometric_checked", st.geometric_checked},
        {"geometric_dropped", st.geometric_dropped},
        {"active_voxels", st.active_voxels},
        {"voxels_above_threshold", st.voxels_above_threshold},
        {"grid_bytes", st.grid_bytes},
        {"depth_store_bytes", fs_stats.store_bytes},
        {"mesh_vertices", st.mesh_vertices},
        {"mesh_triangles", st.mesh_triangles},
        {"carving_frames", st.carving_frames},
        {"occupied_voxels", st.refine.occupied_voxels},
        {"carving_region_voxels", st.refine.region_voxels},
        {"carved_voxels", st.refine.carved},
        {"carved_outside_masks", st.refine.carved_outside_masks},
        {"carving_mask_views", st.refine.mask_views},
        {"preview_views", preview_ids.size()},
        {"carved_per_round", st.refine.carved_per_round},
        {"poisson_points", st.refine.poisson_points},
        {"poisson_depth", st.refine.poisson_depth},
        {"rim_triangles_removed", st.rim_trim.triangles_removed},
        {"smoothed_vertices", st.smoothing.vertices_moved},
        {"smoothing_capped_vertices", st.smoothing.vertices_capped}}},
      {"options",
       {{"densify", options_.densify},
        {"run_filter", options_.depth.run_filter},
        {"surface_threshold", mo.threshold < 0 ? fo.surface_threshold : mo.threshold},
        {"sigma_v", fo.sigma_v},
        {"sigma_s", fo.sigma_s},
        {"background_floor",
         {{"floor", options_.densify ? options_.background_floor.floor : 0.0},
          {"gate_px", options_.background_floor.gate_px},
          {"gate_on_sparse", options_.background_floor.gate_on_sparse}}},
        {"mask_free_space",
         {{"confidence", mask_of_view_ ? options_.mask_free_space.confidence : 0.0},
          {"margin_px", options_.mask_free_space.margin_px}}},
        {"activation_min_confidence", fo.activation_min_confidence},
        {"probability_clamp", fo.probability_clamp},
        {"band", fo.band},
        {"free_space_margin", fo.free_space_margin},
        {"color_views", options_.color_views},
        {"propagation",
         {{"sigma_p", po.photo.sigma_p},
          {"max_view_angle_deg", po.photo.max_view_angle_deg},
          {"silhouette_ratio", po.photo.silhouette_ratio},
          {"dt_sigma_spatial", po.dt_sigma_spatial},
          {"dt_sigma_color", po.dt_sigma_color},
          {"refinement_views", po.refinement.views},
          {"refinement_slanted", po.refinement.slanted}}},
        {"carving", options_.refine && options_.refine_options.carve && st.carving_frames > 0},
        {"carving_mask_margin_px",
         mask_carving ? nlohmann::json(options_.refine_options.carving.mask_margin_px) : nlohmann::json()},
        {"poisson", options_.refine && options_.refine_options.use_poisson},
        {"rim_trim_rounds", options_.rim_trim.rounds},
        {"smooth_iterations", options_.mesh_smoothing.iterations},
        {"smooth_max_displacement_voxels", options_.mesh_smoothing.max_displacement_voxels},
        {"consistency_threshold", options_.refine_options.carving.consistency_threshold},
        {"carving_rounds", options_.refine_options.carving.max_rounds}}},
  };
  for (const auto& [key, value] : options_.extra_report.items()) result.report[key] = value;
  if (write) {
    std::ofstream f(options_.out_dir / "report.json");
    f << result.report.dump(2) << "\n";
    if (!f) throw InputError((options_.out_dir / "report.json").string(), "cannot write");
  }
  return result;
}

}  // namespace lfrecon
