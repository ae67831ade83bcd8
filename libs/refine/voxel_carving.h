#pragma once
// Photo-consistency voxel carving of the fused surface (BRIEF §1.6, paper §5
// "Voxel carving", eqs. 15-16), and the oriented boundary voxels of the
// carved region that go to screened Poisson.
#include <Eigen/Core>
#include <vector>

#include "fusion/mesh_coloring.h"
#include "geometry/pinhole_view.h"
#include "geometry/triangle_mesh.h"
#include "refine/refine_options.h"
#include "refine/voxel_grid.h"

namespace lfrecon {

struct CarvingRound {
  std::size_t judged = 0;   // exposed voxels of R seen by >= min_views views
  std::size_t unseen = 0;   // exposed voxels of R seen by fewer views (kept)
  std::size_t carved = 0;
  // Inconsistent, but kept: as inconsistent deeper (CarvingOptions::require_consistent_behind).
  std::size_t kept_inconsistent_behind = 0;
  double seconds = 0;
};

struct CarvingResult {
  std::size_t region_voxels = 0;  // |R|
  std::size_t occupied_before = 0, occupied_after = 0;
  std::size_t mask_views = 0;          // views with a usable mask
  std::size_t carved_outside_masks = 0;  // before the rounds (CarvingOptions::carve_outside_masks)
  std::vector<CarvingRound> rounds;  // one per round run
  std::size_t TotalCarved() const;   // outside the masks and in every round
};

// Carves `grid` in place, at most options.max_rounds rounds. Each round
// meshes the current grid (the iso-surface), renders its back faces in every
// view for visibility, propagates the mesh normals into R, and carves every
// exposed voxel of R whose weighted colour variance over the views that see
// it (eq. 15-16) is too high. `views`: frames (CV_32FC3 BGR in [0, 1] or
// CV_8UC3) with their geometry; their depth fields are ignored. `masks`:
// empty, or one per view (CV_8U of its size, nonzero = the object; an empty
// Mat: none for that view): the voxels outside them are carved first
// (CarvingOptions::carve_outside_masks). Throws OptionError /
// std::invalid_argument.
CarvingResult VoxelCarving(VoxelGrid* grid, const std::vector<ColorView>& views, const CarvingOptions& options,
                           const std::vector<cv::Mat>& masks = {});

// The voxels CarvingOptions::carve_outside_masks carves: every occupied voxel
// of `grid` that some view of `views` with a mask (`masks[i]` nonempty, with
// an object pixel) has in its image, in front of it, farther than
// `margin_px` + the voxel's projected half-diagonal from every object pixel
// (deterministic order). The grid is not changed.
std::vector<Eigen::Vector3i> VoxelsOutsideMasks(const VoxelGrid& grid, const std::vector<PinholeView>& views,
                                                const std::vector<cv::Mat>& masks, double margin_px,
                                                std::size_t* mask_views = nullptr);

// Photo-consistency of one voxel (eq. 15-16): the weighted colour variance
// PC(v) = Σ w_v(i) ||c_v(i) - μ_v||² / Σ w_v(i) with w_v(i) = n_v · r_{v,i}
// (r: unit vector from v towards view i's centre) where positive and visible.
// `back_depths[i]`: the planar depth of the mesh's back faces in view i
// (CV_32F, 0 where none); `images[i]`: CV_32FC3. Returns -1 when fewer than
// `min_views` views have a positive weight; `views_used` gets their number.
double PhotoConsistencyVariance(const Eigen::Vector3d& center, const Eigen::Vector3d& normal,
                                const std::vector<PinholeView>& views, const std::vector<cv::Mat>& images,
                                const std::vector<cv::Mat>& back_depths, double visibility_tolerance, int min_views,
                                int* views_used = nullptr, double min_cos = 0);

// Planar depth of the nearest *back-facing* triangle at each pixel centre
// (CV_32F, 0 where none): where a ray leaves the first solid it enters.
// Triangles are back-facing when their right-hand normal points away from
// the camera (the mesh's normals point outwards).
cv::Mat RenderBackFaceDepth(const TriangleMesh& mesh, const PinholeView& view);

// Where the H = threshold iso-surface crosses the edges from exposed voxel v
// to its free 6-neighbours (the mean of those marching-cubes vertices); v's
// centre when it has no free neighbour.
Eigen::Vector3d SurfacePoint(const VoxelGrid& grid, const Eigen::Vector3i& v);

struct OrientedPoints {
  std::vector<Eigen::Vector3d> points;
  std::vector<Eigen::Vector3d> normals;  // unit, outward
};

// §5: "we supply all voxels v and their normals n_v on the boundary of R to
// Poisson surface reconstruction". The boundary voxels are the exposed ones;
// each is placed where the H = threshold iso-surface crosses its edges to
// its free 6-neighbours (SurfacePoint) rather than at its centre, which lies
// up to a voxel inside; its normal is the mean of the current mesh's vertex
// normals around it.
OrientedPoints BoundaryPoints(const VoxelGrid& grid);

}  // namespace lfrecon
