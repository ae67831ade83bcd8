#pragma once
// Parameters of the probabilistic depth aggregation (BRIEF §1.5, paper §5),
// with the paper's names and equation numbers. Lengths are in metres unless a
// field says "in voxels" or "in σ_v".
#include <Eigen/Core>

#include "geometry/triangle_mesh.h"

namespace lfrecon {

// How a voxel's projection p_i reads d_i and c_i from view i's maps.
enum class DepthSampling {
  kNearest,   // the pixel that contains p_i
  kBilinear,  // bilinear over the 4 pixels around p_i that share the nearest pixel's label and
              // whose depth lies within the band of its depth (no mixing across silhouettes)
};

struct FusionOptions {
  BoundingBox volume;         // V (world, metres); voxels tile it from volume.min
  double voxel_size = 0.002;  // edge of a voxel (metres)

  // Eq. 11: c_{v,i} = c_i exp(-|d_i - d_{v,i}|^2 / (2 σ_v^2)); σ_v in voxels (paper: one voxel).
  double sigma_v = 1.0;
  // Eqs. 12-13: P_i = N(c;1,σ_s) / (N(c;1,σ_s) + N(c;-1,σ_s)) = 1 / (1 + exp(-2c/σ_s^2)).
  // The paper leaves σ_s open. It sets how many dissenting views a voxel
  // survives: with σ_s = 0.7 a clear surface vote gives P = 0.983 and a clear
  // free-space vote P = 0.017, so a voxel stays above the 0.2 threshold while
  // fewer than ~39 % of the views that see it call it free (σ_s = 0.5: 20 %;
  // σ_s = 1: 74 %, but then the surface moves half a voxel outwards). Must be
  // below 1.2: otherwise P(c = -1) > 0.2 and nothing is ever carved.
  double sigma_s = 0.7;
  // Half-width of the foreground band around d_i, in σ_v: a view's band
  // activates voxels (only active voxels are stored), and a voxel more than
  // this far *behind* d_i is occluded in that view: no evidence, not counted.
  double band = 3.0;
  // Our extension of eq. 11 (the paper gives c ≈ 0, P ≈ ½ in front of a
  // foreground depth, so only background rays carve and the result is close
  // to a visual hull): a voxel more than this many σ_v *in front of* a
  // foreground depth d_i lies on the free part of the viewing ray and gets
  // c_{v,i} = -c_i, as background rays do; eq. 11 applies from there to the
  // band behind d_i. 0 puts the H = 0.2 surface closest to the true one on
  // exact and on noisy (±1 voxel) depth; larger values tolerate depth maps
  // that are biased long. Negative: eq. 11 literally.
  double free_space_margin = 0.0;
  // Nearest: on exact depth slightly more accurate than bilinear (synthetic
  // sphere/box median error 0.5 vs 0.8 mm at 4 mm voxels; figurines F@2mm
  // 0.801 vs 0.800) and cheaper.
  DepthSampling sampling = DepthSampling::kNearest;
  // P_i is clamped to [ε, 1-ε] before the log.
  double probability_clamp = 1e-6;
  // Eq. 14 / §5: the surface is the H = 0.2 iso-surface.
  double surface_threshold = 0.2;
  // Activation: each foreground pixel's band is sampled every half voxel
  // along its ray, by sub-pixel rays at most this many voxels apart where a
  // pixel is wider than that. On the figurines' ground truth at 1 mm, 1.0
  // instead of 0.5 cuts activation 3x and F@2mm by < 0.001 (other views fill
  // the few voxels one view's rays miss).
  double activation_step = 1.0;
  // Only foreground pixels with c_i at least this activate new voxels (all
  // pixels still give evidence to active ones). Dense maps (§4) carry many
  // weak, noisy depths whose bands would otherwise activate most of the
  // grid; the activated set stays a union over views, so order independence holds.
  double activation_min_confidence = 0.0;
  // Pruning (our addition, for speed): every `prune_every` views (0: never),
  // active voxels with H below `prune_below` and no neighbour (26-connected)
  // at or above it are dropped, so each later view updates fewer voxels. It
  // is exact where it matters: a dropped voxel that a later view's band
  // reaches is re-activated and back-filled from every stored view, and one
  // that no band reaches only gets free-space evidence, so it stays below the
  // surface threshold; the cells that straddle the threshold keep their corners.
  int prune_every = 0;
  double prune_below = 0.05;

  // Memory budget of the back-fill store (the CompactDepthViews kept of every
  // integrated view, 4 bytes per pixel: 422 MiB for the figurines' 480
  // 640x360 views, 11 GB for 3000 1280x720 ones). While the store fits, H is
  // exact and order independent. Over the budget, the oldest of the finest
  // stored views are coarsened, 2x2 blocks into one (memory / 4 each time, see
  // CompactDepthView::Coarsened), down to store_max_block pixels per block, so
  // memory stays bounded: the default 1 GiB holds 3000 720p views at 4x4
  // blocks or finer. Only back-fill (voxels activated after a view was
  // coarsened) uses coarsened views; every view's own update is full
  // resolution. Cost: H then depends slightly on the order, and voxels near
  // silhouettes of coarsened views lose some free-space evidence (the object
  // is dilated by up to a block in those views, never eroded: thin features
  // are kept). 0: unlimited (always exact). Once every view is at
  // store_max_block the store grows again, by ~1/store_max_block² of the
  // full size per view (14 KB per 720p view at 16).
  std::size_t store_budget_bytes = std::size_t{1} << 30;
  int store_max_block = 16;  // a power of 2, >= 1

  // Throws OptionError.
  void Check() const;
  // Check() without `volume` and `voxel_size` (options known before the data
  // is: the job or command line options).
  void CheckModel() const;

  double SigmaV() const { return sigma_v * voxel_size; }  // metres
  double BandHalfWidth() const { return band * SigmaV(); }  // metres
  // Voxels along x, y, z covering V.
  Eigen::Vector3i GridSize() const;
};

}  // namespace lfrecon
