#include "pipeline/finish_surface.h"

#include "util/progress.h"

namespace lfrecon {

TaubinSmoothingOptions SmoothingOptions(const PipelineOptions& options, double voxel_size) {
  TaubinSmoothingOptions so;
  so.iterations = options.mesh_smoothing.iterations;
  so.max_displacement = options.mesh_smoothing.max_displacement_voxels * voxel_size;
  so.min_component_vertices = options.mesh_smoothing.min_component_vertices;
  return so;
}

FinishedSurface FinishSurface(const ProbabilisticFusion& fusion, const TriangleMesh& fused,
                              const std::vector<ColorView>& carve, const std::vector<ColorView>& color,
                              const PipelineOptions& options, const std::vector<cv::Mat>& carve_masks) {
  FinishedSurface out;
  if (options.refine) {
    Timer tr;
    RefineResult refined = RefineFusedSurface(fusion, carve, options.refine_options, options.meshing, carve_masks);
    out.refine = refined.stats;
    out.seconds_refine = tr.Seconds();
    out.refined = !refined.mesh.triangles.empty();
    if (out.refined) out.mesh = std::move(refined.mesh);
  }
  // Too few boundary voxels for Poisson (or no refinement): the fused surface rather than nothing.
  if (!out.refined) out.mesh = fused;
  // Rims first: smoothing would pull a ragged rim's triangles in before they go (measured both ways, trimming
  // first kept more F@2).
  Timer ts;
  out.rim_trim = TrimOpenRims(&out.mesh, options.rim_trim);
  out.smoothing = SmoothTaubin(&out.mesh, SmoothingOptions(options, fusion.options().voxel_size));
  out.seconds_smooth = ts.Seconds();
  Timer tc;
  if (!color.empty() && !out.mesh.triangles.empty()) ColorizeMesh(&out.mesh, color, options.coloring);
  out.seconds_color = tc.Seconds();
  return out;
}

bool CarvesOutsideMasks(const PipelineOptions& options) {
  return options.refine && options.refine_options.carve && options.refine_options.carving.carve_outside_masks;
}

}  // namespace lfrecon
