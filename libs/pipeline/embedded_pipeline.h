#pragma once
// The whole reconstruction in one process over one pass of the frames
// (`lfrecon run`): depth from gradients (§3.1) and filtering (§3.2) through
// StreamingDepth, per-view densification by edge-aware propagation (§4), and
// incremental probabilistic fusion (§5) of every view as soon as its depth
// exists; at the end the H = 0.2 iso-surface is meshed and coloured from a few
// frames. Frames are read once, in order; what is held is bounded by the
// neighbourhood windows (frames within 5° of the views still to be densified,
// plus `color_views` frames kept for colouring; 8-bit frames held as CV_8UC3, see
// PipelineOptions::compact_frames), never by the sequence length.
//
// The fused mesh is then refined (§5 end, libs/refine): voxel carving by the
// photo-consistency of `carving_views` kept frames, then the carved grid's
// iso-surface (or, with refine_options.use_poisson, screened Poisson of its
// boundary voxels); mesh_raw stays the fused mesh.
#include <filesystem>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "fusion/mesh_coloring.h"
#include "fusion/probabilistic_fusion.h"
#include "geometry/mesh_rims.h"
#include "geometry/mesh_smoothing.h"
#include "geometry/pinhole_view.h"
#include "geometry/triangle_mesh.h"
#include "io/frame_source.h"
#include "pipeline/pipeline_options.h"
#include "refine/refine.h"

namespace lfrecon {

struct PipelineStats {
  int views = 0;  // views fused
  int frames_read = 0;
  int max_frames_held_depth = 0;     // in StreamingDepth's window
  int max_frames_held_pipeline = 0;  // in the pipeline's densification window
  int max_frames_pending_depth = 0;  // frames of views read but not yet emitted by StreamingDepth
  int color_frames = 0;
  int masked_views = 0;  // views fused with their mask's free space (PipelineOptions::mask_free_space)
  long long sparse_pixels = 0, filtered_pixels = 0, fused_pixels = 0;  // pixels with depth, summed over views
  // PipelineOptions::geometric_consistency: foreground dense depths checked (not the view's own) and dropped.
  long long geometric_checked = 0, geometric_dropped = 0;
  double voxel_size = 0;
  std::size_t active_voxels = 0;
  std::size_t voxels_above_threshold = 0;  // active voxels with H >= the surface threshold
  std::size_t grid_bytes = 0;
  std::size_t mesh_vertices = 0, mesh_triangles = 0;
  // Seconds per stage (depth sparse/filter are StreamingDepth's own totals).
  double seconds_sparse = 0, seconds_filter = 0, seconds_densify = 0, seconds_fusion = 0;
  double seconds_mesh = 0, seconds_color = 0, seconds_write = 0, seconds_total = 0;
  double seconds_refine = 0;  // carving + Poisson (their split is in `refine`)
  double seconds_smooth = 0;  // PipelineOptions::rim_trim and mesh_smoothing
  // Process CPU seconds (user + system, every thread) of the same stages.
  double cpu_sparse = 0, cpu_filter = 0, cpu_densify = 0, cpu_fusion = 0;
  double cpu_mesh = 0, cpu_finish = 0, cpu_write = 0, cpu_total = 0;  // finish: refine + colour
  int carving_frames = 0;
  RefineStats refine;  // when options.refine
  RimTrimStats rim_trim;           // PipelineOptions::rim_trim
  TaubinSmoothingStats smoothing;  // PipelineOptions::mesh_smoothing
  std::int64_t peak_rss_bytes = 0;
};

struct PipelineResult {
  TriangleMesh mesh;      // final (coloured): the refined surface, or the fused one without refinement
  TriangleMesh mesh_raw;  // before carving (the fused mesh, uncoloured)
  PipelineStats stats;
  nlohmann::json report;  // what report.json holds
};

class EmbeddedPipeline {
 public:
  // `views`: geometry of every frame of the sequence (frame k is view k);
  // `names`: image names for depth outputs (empty: 00000, 00001, ...).
  EmbeddedPipeline(std::vector<PinholeView> views, const BoundingBox& volume, const PipelineOptions& options,
                   std::vector<std::string> names = {});

  // Streams `frames` once and runs every stage; writes the outputs when
  // options.out_dir is set. Throws InputError / OptionError.
  PipelineResult Run(FrameSource& frames);

  // Called after each view is fused (view index, views done, views total); for progress or tests.
  void SetViewCallback(std::function<void(int, int, int)> cb) { view_callback_ = std::move(cb); }
  // Object masks (CV_8U of the view's size, nonzero = the object; an empty Mat:
  // none for that view), read when view i is fused, for
  // PipelineOptions::mask_free_space, and for the carving frames once fusion
  // is done, for CarvingOptions::carve_outside_masks. Not set: no masks.
  void SetMasks(std::function<cv::Mat(int)> mask_of_view) { mask_of_view_ = std::move(mask_of_view); }

 private:
  std::vector<PinholeView> views_;
  BoundingBox volume_;
  PipelineOptions options_;
  std::vector<std::string> names_;
  std::function<void(int, int, int)> view_callback_;
  std::function<cv::Mat(int)> mask_of_view_;
};



// What the fusion integrates for a view, in `lfrecon run` and in the service's
// aggregator alike: its dense map with PipelineOptions::background_floor
// applied (`sparse`: the view's sparse map of §3.1, for gate_on_sparse; empty
// if not at hand). NeedsBackgroundFloor: whether it changes anything (else the
// sparse map need not be read).
bool NeedsBackgroundFloor(const PipelineOptions& options);
DepthMap WithBackgroundFloor(const DepthMap& dense, const DepthMap& sparse, const PinholeView& view,
                             const BoundingBox& volume, const PipelineOptions& options);

}  // namespace lfrecon
