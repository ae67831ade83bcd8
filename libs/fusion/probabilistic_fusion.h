#pragma once
// Probabilistic depth aggregation (BRIEF §1.5, paper §5) on a sparse OpenVDB
// grid, streaming: views arrive one by one, in any order, and H can be read at
// any moment.
//
// Per voxel v the grid stores Σ_i log P_i(v ∈ S | c_{v,i}) and the number of
// views i that said something about v, so H(v) = exp(mean log P_i) (eq. 14).
// Only *active* voxels are stored: those that lie in some view's foreground
// band (|d_{v,i} - d_i| <= band·σ_v around a foreground depth). Memory grows
// with the observed surface, not with V's volume.
//
// Integrating view j:
//  (a) activates the voxels of its foreground band (ray marching over its
//      foreground pixels);
//  (b) back-fills the voxels it activated for the first time with the evidence
//      of every view integrated before (kept as CompactDepthViews);
//  (c) adds its own evidence to every active voxel in its frustum (band,
//      free space in front of foreground depths, background rays).
// Every active voxel thus ends with the evidence of every view, whatever the
// order: H is order independent (up to float rounding of the sums).
//
// Memory budget (FusionOptions::store_budget_bytes). The store of (b) grows
// with the sequence (4 bytes per pixel per view: 11 GB for 3000 720p views),
// so over its budget it coarsens stored views, the oldest of the finest
// first, by 2x2 blocks each time (CompactDepthView::Coarsened). Why this
// approximation: back-fill is the only reader of old views, and the voxels it
// serves are activated late — after most views have voted — so they are few
// and mostly off the surface (noise bands, surfaces first seen from a new
// side), where free-space evidence dominates and a block's front-most depth
// gives the same vote as its pixels. What it costs: a late voxel near a
// coarsened view's silhouette gets that view's surface vote instead of its
// free-space vote (the object dilates by up to a block there, never erodes),
// and H depends a little on the order (views integrated early are stored
// coarser). Measured in tests/fusion/probabilistic_fusion_test.cc
// (StoreBudget*) and docs/benchmarks.md ("Fusion at scale").
//
// Not thread-safe: one Integrate at a time (each call is parallel inside).
#include <Eigen/Core>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <memory>

#include "depth/depth_map.h"
#include "fusion/fusion_options.h"
#include "geometry/pinhole_view.h"
#include "geometry/triangle_mesh.h"

namespace lfrecon {

struct MeshingOptions {
  double threshold = -1;  // H iso-value; < 0: FusionOptions::surface_threshold (0.2)
  int min_views = 1;      // cells with a corner seen by fewer views are skipped
  void Check() const;
};

struct FusionStats {
  int views = 0;
  std::size_t active_voxels = 0;
  std::size_t grid_bytes = 0;   // the OpenVDB tree
  std::size_t store_bytes = 0;  // the compact depth maps kept for back-fill
  int store_coarsened_views = 0;  // stored views coarsened for the budget
  int store_max_block = 1;        // largest block (pixels per side) in the store
  double coarsen_s = 0;           // cumulative seconds spent coarsening
  double activate_s = 0, backfill_s = 0, update_s = 0, prune_s = 0;  // cumulative seconds per phase
  std::size_t pruned_voxels = 0;  // dropped by pruning, summed over prunes (re-activated ones count again)
};

class ProbabilisticFusion {
 public:
  explicit ProbabilisticFusion(const FusionOptions& options);  // throws OptionError
  ~ProbabilisticFusion();
  ProbabilisticFusion(ProbabilisticFusion&&) noexcept;
  ProbabilisticFusion& operator=(ProbabilisticFusion&&) noexcept;

  // Adds one view. `depth`: planar depth (CV_32F, 0 = none) of the view's size;
  // confidence (CV_32F in [0, 1]) and label (CV_8U DepthLabel) are optional:
  // without confidence c_i = 1, without labels a depth is foreground when its
  // point lies inside V. `view_id` >= 0 makes it idempotent (a re-issued view
  // is ignored and false returned). Throws std::invalid_argument on a size mismatch.
  bool Integrate(const PinholeView& view, const DepthMap& depth, int view_id = -1);
  bool HasView(int view_id) const;
  // Drops active voxels far below the surface (FusionOptions::prune_below, see
  // there); Integrate calls it every prune_every views. Returns how many.
  std::size_t Prune();

  const FusionOptions& options() const;
  int NumViews() const;
  FusionStats Stats() const;

  // Voxel (i, j, k) has its centre at V.min + (i + ½, j + ½, k + ½) · voxel_size.
  Eigen::Vector3d VoxelCenter(const Eigen::Vector3i& ijk) const;
  Eigen::Vector3i VoxelIndex(const Eigen::Vector3d& world) const;
  // H(v) = exp(Σ log P / n) of an active voxel; 0 where nothing is stored.
  double SurfaceProbability(const Eigen::Vector3i& ijk, int* num_views = nullptr) const;
  bool IsActive(const Eigen::Vector3i& ijk) const;
  // Visits every active voxel (serially, in the tree's deterministic order).
  void ForEachVoxel(const std::function<void(const Eigen::Vector3i& ijk, double sum_log_p, int num_views)>& f) const;

  // The H = threshold iso-surface by marching cubes over cells whose 8 corners
  // are active (so the unobserved inside of a surface's band never makes a
  // second wall). World coordinates, outward normals (towards lower H), no colours.
  TriangleMesh ExtractMesh(const MeshingOptions& options = {}) const;

  // Writes an OpenVDB file with float grids "surface_probability" (H),
  // "log_p_sum" and "view_count", in world coordinates (voxel centres).
  void WriteVdb(const std::filesystem::path& path) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace lfrecon
