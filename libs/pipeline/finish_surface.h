#pragma once
// The steps after fusion, one function for `lfrecon run` and the service's
// refined export: refinement of the fused grid (voxel carving, then marching
// cubes or screened Poisson: RefineFusedSurface), the fused mesh where the
// refinement made nothing (too few boundary voxels for Poisson), then colour.
#include <vector>

#include "fusion/mesh_coloring.h"
#include "fusion/probabilistic_fusion.h"
#include "geometry/mesh_rims.h"
#include "geometry/mesh_smoothing.h"
#include "geometry/triangle_mesh.h"
#include "pipeline/pipeline_options.h"
#include "refine/refine.h"

namespace lfrecon {

struct FinishedSurface {
  TriangleMesh mesh;  // refined (or the fused mesh), coloured when colour frames were given
  RefineStats refine;
  bool refined = false;  // options.refine and it made a surface
  RimTrimStats rim_trim;           // PipelineOptions::rim_trim
  TaubinSmoothingStats smoothing;  // PipelineOptions::mesh_smoothing
  double seconds_refine = 0, seconds_smooth = 0, seconds_color = 0;  // smooth: rim trim + smoothing
};

// `fused`: the grid's iso-surface (ExtractMesh(options.meshing)); `carve`: the
// carving frames (ReconstructionPlan::carving_frames), `color`: the colour frames;
// `carve_masks`: empty, or the object mask of each carving frame (empty Mats
// where a frame has none; CarvingOptions::carve_outside_masks).
// Without options.refine the mesh is `fused`. Either then loses its open rims
// (options.rim_trim), is smoothed (options.mesh_smoothing) and coloured.
FinishedSurface FinishSurface(const ProbabilisticFusion& fusion, const TriangleMesh& fused,
                              const std::vector<ColorView>& carve, const std::vector<ColorView>& color,
                              const PipelineOptions& options, const std::vector<cv::Mat>& carve_masks = {});

// The Taubin options of PipelineOptions::mesh_smoothing for a grid of `voxel_size` metres.
TaubinSmoothingOptions SmoothingOptions(const PipelineOptions& options, double voxel_size);

// Whether FinishSurface uses `carve_masks` (the refinement carves outside the
// masks: options.refine, carving on, CarvingOptions::carve_outside_masks), so
// a caller reads the carving frames' masks only then (`lfrecon run`, the
// service's refined export).
bool CarvesOutsideMasks(const PipelineOptions& options);

}  // namespace lfrecon
