#include "pipeline/pipeline_flags.h"

#include <cmath>

#include "util/error.h"

namespace lfrecon {

PipelineOptions OptionsFromFlags(const ReconstructionFlags& f) {
  PipelineOptions options;
  if (!(f.voxel_size >= 0) || !std::isfinite(f.voxel_size)) throw OptionError("voxel size (--voxel-mm) must be positive");
  options.voxel_size = f.voxel_size;
  options.densify = !f.no_densify;
  if (f.color_views) options.color_views = *f.color_views;
  if (!(f.sigma_s >= 0) || !std::isfinite(f.sigma_s)) throw OptionError("sigma_s (--sigma-s) must be positive");
  if (f.sigma_s > 0) (options.densify ? options.dense_sigma_s : options.fusion.sigma_s) = f.sigma_s;
  options.selection.enabled = !f.all_views;
  if (f.max_frame_gap) {
    if (*f.max_frame_gap < 0) throw OptionError("--max-frame-gap must be >= 0 (0: no limit)");
    options.depth.max_frame_gap = *f.max_frame_gap;
  }
  if (f.no_mask_free_space) options.mask_free_space.confidence = 0;
  if (f.no_geometric_consistency) options.geometric_consistency.enabled = false;
  if (f.mask_carving) options.refine_options.carving.carve_outside_masks = true;
  if (f.chroma_weight) {
    if (!(*f.chroma_weight >= 0 && *f.chroma_weight <= 1)) throw OptionError("--chroma-weight must be in [0, 1]");
    options.propagation.photo.chroma_weight = *f.chroma_weight;
  }
  if (f.view_step_deg) {
    if (!(*f.view_step_deg > 0 && *f.view_step_deg < 90)) throw OptionError("--view-step-deg must be in (0, 90)");
    if (f.all_views) throw OptionError("--view-step-deg and --all-views exclude each other");
    options.selection.min_step_deg = *f.view_step_deg;
  }
  if (f.refine_depth_views) {
    if (*f.refine_depth_views < 0) throw OptionError("--refine-depth-views must be >= 0 (0: no refinement)");
    options.propagation.refinement.views = *f.refine_depth_views;
  }
  if (f.smooth_iterations) {
    if (*f.smooth_iterations < 0) throw OptionError("--smooth-iterations must be >= 0 (0: no smoothing)");
    options.mesh_smoothing.iterations = *f.smooth_iterations;
  }
  if (f.rim_trim_rounds) {
    if (*f.rim_trim_rounds < 0) throw OptionError("--rim-trim-rounds must be >= 0 (0: no trimming)");
    options.rim_trim.rounds = *f.rim_trim_rounds;
  }
  options.Check();
  return options;
}

}  // namespace lfrecon
