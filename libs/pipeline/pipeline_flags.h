#pragma once
// The one mapping from a reconstruction's user-facing flags to PipelineOptions:
// `lfrecon run`'s flags and a service job's JobOptions (services/common/job_store.cc,
// from `lfrecon submit`'s flags) both go through OptionsFromFlags, so a job and
// a run with the same flags get the same options.
#include <optional>

#include "pipeline/pipeline_options.h"

namespace lfrecon {

struct ReconstructionFlags {
  double voxel_size = 0;           // metres; 0: V's longest side / 256 (--voxel-mm / 1000)
  double sigma_s = 0;              // σ_s of eq. 12-13; 0: the default (dense 0.15, sparse 0.7) (--sigma-s)
  bool no_densify = false;         // fuse the filtered sparse maps (--no-densify)
  std::optional<int> color_views;  // frames that colour the mesh; unset: the default (--color-views)
  bool all_views = false;          // no view selection: every view gets depth and fusion (--all-views)
  // Views further apart in the sequence are never neighbours (StreamingDepthOptions::max_frame_gap;
  // 0: no limit); unset: the default (1000). An open stream's views are processed
  // two gaps behind its newest frame (ReconstructionPlan::SettledFrames).
  std::optional<int> max_frame_gap;
  // Object masks give V only (--no-mask-free-space): PipelineOptions::mask_free_space off.
  bool no_mask_free_space = false;
  // PipelineOptions::geometric_consistency off (--no-geometric-consistency).
  bool no_geometric_consistency = false;
  // Object masks also carve the fused voxels outside them (--mask-carving):
  // CarvingOptions::carve_outside_masks on (used where the refinement carves).
  bool mask_carving = false;
  // Weight of chroma in ρ's colour test (eq. 9), in [0, 1]: PhotoconsistencyOptions::chroma_weight
  // (propagation/colour_difference.h); unset: its default (--chroma-weight).
  std::optional<double> chroma_weight;
  // Degrees between consecutive selected views (ViewSelectionOptions::min_step_deg, > 0 and < 90);
  // unset: its default (--view-step-deg).
  std::optional<double> view_step_deg;
  // Neighbours of the dense depth's photometric refinement (PhotometricRefinementOptions::views,
  // >= 0; 0: off); unset: the default (--refine-depth-views).
  std::optional<int> refine_depth_views;
  // Taubin iterations of the final mesh (PipelineOptions::mesh_smoothing, >= 0; 0: off); unset: the
  // default (--smooth-iterations).
  std::optional<int> smooth_iterations;
  // Rounds of rim trimming of the final mesh (PipelineOptions::rim_trim, >= 0; 0: off); unset: the
  // default (--rim-trim-rounds).
  std::optional<int> rim_trim_rounds;
};

// PipelineOptions defaults with the flags applied; checked (PipelineOptions::Check). Throws OptionError.
PipelineOptions OptionsFromFlags(const ReconstructionFlags& flags);

}  // namespace lfrecon
