#include "pipeline/pipeline_options.h"

#include <cmath>

#include "util/error.h"

namespace lfrecon {

void PipelineOptions::Check() const {
  depth.Check();
  if (densify) propagation.Check();
  if (!(voxel_size >= 0) || !std::isfinite(voxel_size)) throw OptionError("voxel size must be positive");
  if (voxel_size == 0 && voxel_divisions < 1) throw OptionError("voxel_divisions must be >= 1");
  meshing.Check();
  coloring.Check();
  geometric_consistency.Check();
  if (color_views < 0) throw OptionError("color_views must be >= 0");
  if (refine) refine_options.Check();
  rim_trim.Check();
  LFRECON_CHECK_OPTION(mesh_smoothing.iterations >= 0);
  LFRECON_CHECK_OPTION(mesh_smoothing.max_displacement_voxels > 0);
  LFRECON_CHECK_OPTION(mesh_smoothing.min_component_vertices >= 0);
  if (carving_views < 0) throw OptionError("carving_views must be >= 0");
  if (preview_views < 0) throw OptionError("preview_views must be >= 0");
  selection.Check();
  if (!extra_report.is_object()) throw OptionError("extra_report must be a JSON object");
  if (!(dense_sigma_s > 0)) throw OptionError("dense_sigma_s must be positive");
  // The fusion as Run() sets it up (σ_s of dense maps), but for V and the voxel size.
  FusionOptions fo = fusion;
  if (densify) fo.sigma_s = dense_sigma_s;
  fo.CheckModel();
  if (!(background_floor.floor >= 0 && background_floor.floor <= 1))
    throw OptionError("background_floor.floor must be in [0, 1]");
  if (!(std::isfinite(background_floor.gate_px) && background_floor.gate_px >= 0))
    throw OptionError("background_floor.gate_px must be finite and >= 0");
  if (!(mask_free_space.confidence >= 0 && mask_free_space.confidence <= 1))
    throw OptionError("mask_free_space.confidence must be in [0, 1]");
  if (!(std::isfinite(mask_free_space.margin_px) && mask_free_space.margin_px >= 0))
    throw OptionError("mask_free_space.margin_px must be finite and >= 0");
}

double PipelineVoxelSize(const BoundingBox& volume, const PipelineOptions& options) {
  if (options.voxel_size > 0) return options.voxel_size;
  return volume.Extent().maxCoeff() / options.voxel_divisions;
}

FusionOptions PipelineFusionOptions(const PipelineOptions& options, const BoundingBox& volume) {
  FusionOptions fo = options.fusion;
  fo.volume = volume;
  fo.voxel_size = PipelineVoxelSize(volume, options);
  if (options.densify) fo.sigma_s = options.dense_sigma_s;
  fo.Check();
  return fo;
}

}  // namespace lfrecon
