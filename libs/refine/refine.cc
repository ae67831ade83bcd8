#include "refine/refine.h"

#include <spdlog/spdlog.h>

#include <stdexcept>
#include <string>

#include "util/error.h"
#include "util/progress.h"

namespace lfrecon {

void RefineOptions::Check() const {
  carving.Check();
  poisson.Check();
  LFRECON_CHECK_OPTION(max_views >= 0);
}

RefineResult RefineFusedSurface(const ProbabilisticFusion& fusion, const std::vector<ColorView>& views,
                                const RefineOptions& options, const MeshingOptions& meshing,
                                const std::vector<cv::Mat>& masks) {
  options.Check();
  meshing.Check();
  if (!masks.empty() && masks.size() != views.size())
    throw std::invalid_argument("RefineFusedSurface: " + std::to_string(masks.size()) + " masks for " +
                                std::to_string(views.size()) + " views");
  Timer total;
  RefineResult result;
  RefineStats& st = result.stats;
  const double threshold = meshing.threshold < 0 ? fusion.options().surface_threshold : meshing.threshold;

  Timer tg;
  VoxelGrid grid = VoxelGrid::FromFusion(fusion, threshold, meshing.min_views);
  st.occupied_voxels = grid.CountOccupied();
  st.seconds_grid = tg.Seconds();

  if (options.carve && !views.empty()) {
    std::vector<ColorView> used;
    std::vector<cv::Mat> used_masks;
    const std::size_t k = options.max_views > 0 ? std::min<std::size_t>(options.max_views, views.size()) : views.size();
    for (std::size_t c = 0; c < k; ++c) {
      used.push_back(views[c * views.size() / k]);
      if (!masks.empty()) used_masks.push_back(masks[c * views.size() / k]);
    }
    st.carving_views = static_cast<int>(used.size());
    Timer tc;
    const CarvingResult cr = VoxelCarving(&grid, used, options.carving, used_masks);
    st.seconds_carving = tc.Seconds();
    st.region_voxels = cr.region_voxels;
    for (const CarvingRound& r : cr.rounds) st.carved_per_round.push_back(r.carved);
    st.mask_views = static_cast<int>(cr.mask_views);
    st.carved_outside_masks = cr.carved_outside_masks;
    st.carved = cr.TotalCarved();
  }

  Timer tp;
  if (options.use_poisson) {
    const OrientedPoints points = BoundaryPoints(grid);
    PoissonStats ps;
    BoundingBox v = fusion.options().volume;
    result.mesh = ScreenedPoissonSurface(points, grid.voxel_size(), options.poisson, v, &ps);
    st.poisson_points = ps.points;
    st.poisson_depth = ps.depth;
  } else {
    result.mesh = grid.ExtractMesh();
  }
  st.seconds_poisson = tp.Seconds();
  st.mesh_vertices = result.mesh.vertices.size();
  st.mesh_triangles = result.mesh.triangles.size();
  st.seconds_total = total.Seconds();
  const std::string surface = options.use_poisson ? fmt::format("Poisson of {} points (depth {})", st.poisson_points,
                                                                  st.poisson_depth)
                                                   : std::string("marching cubes of the carved grid");
  spdlog::info("refine: {} occupied voxels, |R| {}, {} carved from {} views ({} outside the masks of {}); {}: {} "
               "triangles; {:.1f} s ({:.1f} grid, {:.1f} carving, {:.1f} {})",
               st.occupied_voxels, st.region_voxels, st.carved, st.carving_views, st.carved_outside_masks,
               st.mask_views, surface, st.mesh_triangles,
               st.seconds_total, st.seconds_grid, st.seconds_carving, st.seconds_poisson,
               options.use_poisson ? "Poisson" : "meshing");
  return result;
}

}  // namespace lfrecon
