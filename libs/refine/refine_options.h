#pragma once
// Parameters of the refinement after fusion (BRIEF §1.6, paper §5 "Voxel
// carving"): photo-consistency carving of the fused surface, then screened
// Poisson surface reconstruction (Kazhdan & Hoppe 2013) of the carved
// boundary voxels with their normals.
namespace lfrecon {

struct CarvingOptions {
  // §5: "a region of interest R inside the mesh, which is 3 voxels deep from the surface".
  int region_depth = 3;
  // §5: "We performed a maximum of 3 iterations"; carving stops earlier when a round carves nothing.
  int max_rounds = 3;
  // §5: carve voxels whose photo-consistency is below 0.95. Eq. 16 defines
  // PC(v) as the weighted colour variance Σ w ||c - μ||² / Σ w, which is small
  // when consistent, so the 0.95 is read on the consistency scale 1 - PC(v)
  // with BGR colours in [0, 1]: a voxel is carved when its weighted variance
  // exceeds 0.05 (e.g. two equally weighted colours more than 0.45 apart).
  // Ours: 0.97 (variance 0.03). With require_consistent_behind a correct
  // surface is no longer carved for looking inconsistent, so the stricter test
  // takes more of the halos: on the quality table thin recall and F@5 rose on
  // every set, F@2 on four of six (thin-degraded 0.955 -> 0.992; figurines
  // -0.002, figurines-noisy -0.004), docs/benchmarks.md "Carving only where it
  // can help".
  double consistency_threshold = 0.97;
  // A voxel is judged only when at least this many views see it with w_v(i) > 0 (eq. 15).
  int min_views = 2;
  // Views seeing a voxel more obliquely (w_v(i) = n_v · r_{v,i} below this)
  // get weight 0. Eq. 15 keeps every positive weight (0 here).
  double min_cos = 0;
  // Visibility (§5: render the back faces of the current mesh; v is visible
  // when nearer than them): slack in voxels for a voxel lying on the back
  // face itself (a one-voxel-thin feature).
  double visibility_tolerance = 0.5;
  // Where a voxel's colours c_v(i) are sampled: true, at its SurfacePoint (where
  // the current iso-surface crosses its edges to free space); false, at its
  // centre. The centre of a voxel of a correct surface lies up to a voxel
  // behind it, so views at different angles see surface points up to
  // voxel·tan(angle) apart and a textured surface looks inconsistent (on the
  // textured test sphere, 4 mm voxels, 95th percentile of the variance
  // PC 0.041 at the centres, i.e. several % of the true surface carved per
  // round), while a spurious voxel's surface point still floats in front of
  // the true surface and sees different colours.
  bool sample_at_surface = true;
  // Voxels next to the unobserved inside (an unknown 6-neighbour) are never
  // carved: the fused shell is only about band (3 σ_v) voxels thick, and
  // carving through it would open the surface into the unobserved inside,
  // whose wall is not meshed, and hand Poisson points of that wall.
  bool keep_inner_wall = true;
  // A voxel that fails the test is carved only when carving it can help: the
  // points 1, 2 .. region_depth voxels deeper along its normal are judged in
  // turn, and it is carved at the first that looks consistent or that lies
  // in observed free space (a thin part, a floater or a sheet seen through),
  // or when too few views see any of them; it is kept when every one seen
  // looks inconsistent too (up to R's depth or the unobserved inside). A
  // correct surface that looks inconsistent for another reason (pose error,
  // aliasing on strong texture) looks as inconsistent deeper, and stays; a
  // halo or blob in front of the true surface is carved as before. On the
  // quality table (at consistency 0.95) it raised F@2 on the occlusion scene
  // 0.799 -> 0.835 with thin recall within 0.002 (docs/benchmarks.md,
  // "Carving only where it can help"); judging one voxel deeper only gave
  // 0.851 there but cost the degraded tabletop's thin recall 0.016.
  bool require_consistent_behind = true;
  // Object masks (ours), when the views come with them (VoxelCarving's
  // `masks`): before the photo-consistency rounds, every occupied voxel that a
  // view with a mask has in its image (in front of it) farther than
  // mask_margin_px plus the voxel's own projected half-diagonal from every
  // object pixel of that mask is carved: no part of it is on the object, so it
  // is halo or background (a visual hull, one view suffices). Visibility does
  // not enter: a silhouette bounds the object whatever hides what. Every
  // occupied voxel is judged, not only R's exposed ones, so a halo thicker than
  // R goes at once; a voxel next to the unobserved inside may go too (that
  // inside is outside the mask as well). mask_margin_px is the fusion's
  // (PipelineOptions::mask_free_space): a mask drawn a pixel or two tight keeps
  // the object's rim. Masks with no object pixel are ignored.
  // Off by default: on generated tabletops with masks (docs/benchmarks.md,
  // "Masks in carving") it cost 0.02 thin recall and gained no F-score; likely
  // because a mask that labels pixel centres misses a rod thinner than a pixel
  // wherever it falls between them, and one such view carves the rod there.
  bool carve_outside_masks = false;
  double mask_margin_px = 2.0;
  // Only the exposed voxels of R (with a free 6-neighbour) are judged in a
  // round, so each round peels at most one layer and carving can never hollow
  // out R from inside: a voxel behind the surface would see different surface
  // points in different views and look inconsistent even on a correct
  // textured surface. With region_depth = max_rounds = 3 carving reaches the
  // whole of R, as in the paper.

  void Check() const;  // throws OptionError
};

struct PoissonOptions {
  // Octree depth of the screened Poisson solve; 0: the smallest depth whose
  // finest cells are no larger than a voxel over the points' bounding cube
  // (scaled by `scale`).
  int depth = 0;
  double scale = 1.1;      // the solve's cube over the points' bounding cube (Open3D/PoissonRecon default)
  bool linear_fit = true;  // iso-vertices by linear interpolation (closer to the samples)
  // Trimming (Poisson closes every surface, also across unobserved parts):
  // vertices whose density (PoissonRecon's sampling-density estimate) is
  // below this quantile of all vertex densities are removed ...
  double density_quantile = 0.02;
  // ... and those farther than this many voxels from every input point.
  // <= 0: no distance trimming.
  double max_point_distance = 2.0;
  // Threads of PoissonRecon's OpenMP loops (-1: all cores). One by default:
  // with other work on the cores, libgomp's spin-waiting makes 2 threads much
  // slower than 1 (18k points, depth 7, on a busy 2-core machine: 13.8 s
  // with 2 threads, 2.9 s with 1, 2.4 s with 2 and OMP_WAIT_POLICY=passive).
  int threads = 1;

  void Check() const;  // throws OptionError
};

struct RefineOptions {
  bool carve = true;  // false: Poisson of the fused surface's boundary voxels only
  CarvingOptions carving;
  // true: the surface is the screened Poisson surface of the carved grid's
  // boundary voxels (the paper); false: the marching-cubes iso-surface of the
  // carved grid (the fused surface minus what carving removed). Poisson
  // smooths the thin parts away and closes open surfaces with membranes:
  // on the figurines' dense maps (fusion_from_depth_bench --refine cp,c)
  // F@5mm / thin recall@5mm are 0.617 / 0.636 with Poisson, 0.647 / 0.696
  // with marching cubes (fused: 0.647 / 0.685).
  bool use_poisson = false;
  PoissonOptions poisson;
  // At most this many colour views are used for carving (evenly spread over
  // those given); 0: all given.
  int max_views = 0;

  void Check() const;  // throws OptionError
};

}  // namespace lfrecon
