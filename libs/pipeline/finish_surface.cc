#include "pipeline/finish_surface.h"

#include "util/progress.h"

namespace lfrecon {

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
  Timer tc;
  if (!color.empty() && !out.mesh.triangles.empty()) ColorizeMesh(&out.mesh, color, options.coloring);
  out.seconds_color = tc.Seconds();
  return out;
}

bool CarvesOutsideMasks(const PipelineOptions& options) {
  return options.refine && options.refine_options.carve && options.refine_options.carving.carve_outside_masks;
}

}  // namespace lfrecon
