#pragma once
// The refinement stage after fusion (BRIEF §1.6, paper §5 end): photo-
// consistency voxel carving of the fused surface, then screened Poisson of
// the carved boundary voxels with their normals. The pipeline calls
// RefineFusedSurface once, after the last view is fused.
#include <vector>

#include "fusion/mesh_coloring.h"
#include "fusion/probabilistic_fusion.h"
#include "geometry/triangle_mesh.h"
#include "refine/refine_options.h"
#include "refine/screened_poisson.h"
#include "refine/voxel_carving.h"

namespace lfrecon {

struct RefineStats {
  std::size_t occupied_voxels = 0;  // H >= threshold before carving
  std::size_t region_voxels = 0;    // |R|
  int carving_views = 0;
  std::vector<std::size_t> carved_per_round;
  int mask_views = 0;                    // carving views with a usable object mask
  std::size_t carved_outside_masks = 0;  // before the rounds (CarvingOptions::carve_outside_masks)
  std::size_t carved = 0;                // in all: outside the masks and in every round
  std::size_t poisson_points = 0;
  int poisson_depth = 0;
  std::size_t mesh_vertices = 0, mesh_triangles = 0;
  // seconds_poisson: the final surface (Poisson, or marching cubes of the carved grid)
  double seconds_grid = 0, seconds_carving = 0, seconds_poisson = 0, seconds_total = 0;
};

struct RefineResult {
  TriangleMesh mesh;  // the Poisson surface, trimmed, outward normals, no colours
  RefineStats stats;
};

// `views`: colour frames with their geometry (e.g. the frames the pipeline
// keeps for colouring; at most options.max_views of them, evenly spread, are
// used); their depth fields are ignored. `meshing`: the threshold and
// min_views the fused mesh was extracted with. `masks`: empty, or the object
// mask of each view (VoxelCarving). Throws OptionError /
// std::invalid_argument.
RefineResult RefineFusedSurface(const ProbabilisticFusion& fusion, const std::vector<ColorView>& views,
                                const RefineOptions& options, const MeshingOptions& meshing = {},
                                const std::vector<cv::Mat>& masks = {});

}  // namespace lfrecon
