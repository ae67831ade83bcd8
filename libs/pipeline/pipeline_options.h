#pragma once
// The options of a reconstruction (`lfrecon run` and a service job alike):
// every stage's parameters, which views are processed, what is written.
// ReconstructionPlan (reconstruction_plan.h) turns them and the cameras into
// the job's plan; OptionsFromFlags (pipeline_flags.h) is the one mapping from
// the command-line / job flags to them.
#include <filesystem>
#include <nlohmann/json.hpp>
#include <vector>

#include "depth/streaming_depth.h"
#include "fusion/fusion_options.h"
#include "fusion/geometric_consistency.h"
#include "fusion/mesh_coloring.h"
#include "geometry/mesh_rims.h"
#include "geometry/triangle_mesh.h"
#include "propagation/depth_propagator.h"
#include "refine/refine.h"

namespace lfrecon {

// View selection on dense sequences (ours; the paper processes every view).
// Greedily along the sequence: view 0, then each view whose viewing direction
// is at least min_step_deg from the last view selected, so consecutive
// selected views are at least that far apart. Every frame is still read and
// serves as a depth / photoconsistency neighbour of the selected views; only
// the selected views get depth maps of their own, densification and fusion.
// Only the selected views vote in the §3.2 filter (PlanDepth), so no other
// view needs a sparse map. Views closer than 2° add little that their
// neighbours' maps do not, and fusing fewer of them gave more precise meshes:
// on the figurines (0.75° apart) `lfrecon run` took 289 CPU-s with every view,
// 140 with every second (1°, "Fewer views, relative vote saturation" in
// docs/benchmarks.md) and 95 with every third (2°), F@5mm 0.827 -> 0.836 ->
// 0.843, thin recall 0.874 -> 0.899 -> 0.906; at 2° every set of the quality
// table gained F@5mm and halved its CPU ("View step 2°"). The demo (1.5°
// apart) keeps every second view.
struct ViewSelectionOptions {
  bool enabled = true;        // false: every view (lfrecon run / submit --all-views)
  double min_step_deg = 2.0;  // degrees between consecutive selected views; 0: every view
  void Check() const;         // throws OptionError
};

struct PipelineOptions {
  StreamingDepthOptions depth;
  // §4 densification of each filtered map before fusion; false fuses the
  // filtered sparse maps directly.
  bool densify = true;
  // The densification's photoconsistency adds up at most 12 of the views
  // within 5° (PhotoconsistencyOptions::max_views, spread evenly by angle):
  // a 720p view of the 3000-frame loop (0.12° apart, ~20 grid views within
  // 5°) densified in 0.53 s instead of 0.59 s, mesh F@5mm 0.914 -> 0.915,
  // thin recall 0.989 -> 0.989; sets with 12 or fewer such views are unchanged
  // (docs/benchmarks.md, "Reference patches sampled once").
  //
  // Each propagated foreground depth is searched again by ZNCC over the 4
  // widest-baseline neighbours within 5° (PhotometricRefinementOptions::views;
  // the library default stays 0 = off, as §4). Quality table
  // (docs/benchmarks.md, "Dense depths searched again"), with the refined
  // depths' confidences raised: figurines F@2mm 0.684 -> 0.782, F@5mm 0.900 ->
  // 0.935; figurines-noisy F@2 0.639 -> 0.743, F@5 0.888 -> 0.924; the four
  // generated 320x180 sets within 0.005.
  PropagationOptions propagation = [] {
    PropagationOptions p;
    p.photo.max_views = 12;
    p.refinement.views = 4;
    return p;
  }();
  // Fusion parameters; volume and voxel_size are set by the pipeline. Dense
  // depths weaker than c = 0.01 give evidence but activate no voxels. Measured
  // with fusion_from_depth_bench (σ_s 0.15) as F@5mm / thin recall@5mm:
  //   min c      0            0.01         0.03         0.05
  //   figurines  0.618/0.686  0.647/0.685  0.681/0.681  0.690/0.643
  //   demo       0.795/0.500  0.808/0.403  0.809/0.219  -
  // (demo: the synthetic tabletop of deploy/demo.sh, 320x180). Higher values
  // are faster and more precise but lose thin parts, whose dense depths are
  // the weakest; 0.01 keeps the figurines' thin recall. Pruning (prune_every)
  // stays off: the voxels it drops keep coming back, and back-filling them
  // cost more than it saved (figurines: 208 s of back-fill in a 253 s fusion).
  //
  // P_i is clamped to [0.03, 0.97] (FusionOptions::probability_clamp; the
  // library default is 1e-6): one view's free-space vote then weighs at most
  // log 0.03 = -3.5 instead of -13.8, so a voxel survives a few views whose
  // dense maps put the background where it is (a silhouette one or two pixels
  // off wipes out a stick 3-5 pixels wide), while space that most views see
  // as free is still carved. fusion_from_depth_bench --probability-clamp,
  // F@2mm / F@5mm / P@5mm / thin recall@5mm of the fused mesh:
  //   clamp      1e-6                     0.01                     0.03
  //   figurines  0.462/0.647/0.701/0.685  0.473/0.653/0.696/0.742  0.468/0.651/0.683/0.774
  //   demo       0.492/0.808/0.864/0.403  0.640/0.832/0.875/0.400  0.653/0.836/0.868/0.386
  // (0.1: demo 0.563/0.812/0.805/0.359.)
  FusionOptions fusion = [] {
    FusionOptions f;
    f.activation_min_confidence = 0.01;
    f.probability_clamp = 0.03;
    // The background free-space floor is background_floor below (not the fusion's).
    return f;
  }();
  // σ_s of eq. 12-13 used instead of fusion.sigma_s when the maps are dense:
  // the dense confidence |C'_fg - C'_bg| (§4) averages ~0.1 on the foreground
  // (measured on the synthetic sphere) where the sparse one is ~1, so σ_s must
  // shrink with it for a single view's evidence to matter. On the sphere test
  // (180 views, 4 mm voxels) F@8mm is 0.974 / 0.989 / 0.965 / 0.828 / 0.551 /
  // 0 for σ_s 0.1 / 0.15 / 0.2 / 0.3 / 0.4 / 0.7.
  double dense_sigma_s = 0.15;
  // Background free space (ours), dense maps only: before fusion, background
  // depths whose ray passes V (WithGatedBackgroundFloor) at least gate_px
  // pixels from every foreground depth of the dense map get confidence at
  // least `floor`. Why: the dense background confidence |C'_fg - C'_bg| (§4) is
  // ~0.002-0.05 wherever the background has little texture, and with σ_s 0.15
  // a voxel whose views say "free" that weakly stays above H = 0.2, so the
  // halo that the propagation puts over plain background next to the object
  // (a quarter of the figurines' dense foreground depths lie > 4 cm in front of
  // the truth; docs/benchmarks.md "Where the figurines' precision goes")
  // survives in the mesh. Within the gate the labels are not trusted: a thin
  // part a view's dense map missed is background there.
  // gate_on_sparse: pixels near a depth of the view's *sparse* map (§3.1,
  // before the filter) that lies inside V also gate, so a thin part whose
  // sparse depths the filter or the propagation lost in this view is not carved
  // by it. Quality table, 0.05 / 6 px (F@5mm / thin recall@5mm):
  //   set                 off            gate on dense only   + gate_on_sparse
  //   figurines           0.787 / 0.853  0.815 / -            0.810 / 0.854
  //   thin-degraded       0.634 / 0.452  0.329 / 0.184        0.634 / 0.452
  //   tabletop-degraded   0.830 / 0.233  0.841 / 0.320        0.830 / 0.233
  //   tabletop            0.863 / 0.403  0.865 / 0.409        0.863 / 0.403
  //   figurines-noisy     0.781 / 0.786  -                    0.792 / 0.785
  //   occlusion-degraded  0.920 / -      -                    0.920 / -
  // (docs/benchmarks.md). On by default; the service applies the same
  // WithBackgroundFloor (embedded_pipeline.h) to the stored maps.
  struct BackgroundFloor {
    double floor = 0.05;  // 0: off
    double gate_px = 6.0;
    bool gate_on_sparse = true;
  } background_floor;
  // Free space from object masks (ours), when the job has masks (a masks/
  // folder, an alpha channel, Nerfstudio's mask_path; EmbeddedPipeline::SetMasks):
  // before fusion, each pixel more than margin_px from its mask's object sees
  // empty space through V (WithMaskFreeSpace, after the background floor)
  // with confidence >= `confidence`. Why: the halo the propagation spreads
  // over plain background (see background_floor) is what costs precision, and
  // a mask says where it is. 0.1 reaches the fusion's probability clamp (0.03
  // at dense_sigma_s 0.15) like the floor's 0.05 does; margin_px keeps a mask
  // drawn a pixel or two tight from carving the object's rim.
  struct MaskFreeSpace {
    double confidence = 0.1;  // 0: masks give V only
    double margin_px = 2.0;
  } mask_free_space;
  // Multi-view geometric consistency of the dense maps before fusion
  // (fusion/geometric_consistency.h says what it measured). On by default, in
  // lfrecon run and the service alike; --no-geometric-consistency turns it off.
  GeometricConsistencyOptions geometric_consistency;
  // Voxel edge in metres; <= 0: the longest side of V / voxel_divisions.
  double voxel_size = 0;
  int voxel_divisions = 256;
  MeshingOptions meshing;  // threshold < 0: fusion.surface_threshold (0.2)
  // Frames kept (evenly spread over the processed views) to colour the mesh; 0: no colours.
  int color_views = 8;
  ColoringOptions coloring;
  // Refinement after fusion (BRIEF §1.6): voxel carving, then marching cubes of
  // the carved grid (screened Poisson with refine_options.use_poisson);
  // false: the final mesh is the fused iso-surface.
  bool refine = true;
  RefineOptions refine_options;
  // The final mesh (after the refinement, before colour) loses the triangles on
  // its open rims (geometry/mesh_rims.h), then is Taubin-smoothed
  // (geometry/mesh_smoothing.h): rims lie off the surface more often than the
  // rest, and the iso-surface's vertices carry the fused field's noise.
  // Together they raised F@2 and F@5 on every set of the quality table but
  // one (docs/benchmarks.md, "Open rims trimmed and the mesh smoothed", with
  // what they cost thin recall). mesh_raw.ply stays the fused iso-surface.
  RimTrimOptions rim_trim;  // rounds 0: off (--rim-trim-rounds)
  struct MeshSmoothing {
    int iterations = 6;                   // λ|μ pairs (λ 0.5, μ -0.53); 0: off (--smooth-iterations)
    double max_displacement_voxels = 1;  // no vertex moves farther than this many voxels
    int min_component_vertices = 100;    // smaller components (thin fragments) are left alone
  } mesh_smoothing;
  // Frames kept (evenly spread over the processed views) for carving's
  // photo-consistency (eqs. 15-16); frames also kept for colour share pixels.
  int carving_views = 24;
  // Hold the frames of the densification window and the colour/carving frames
  // as CV_8UC3 when they are exactly 8-bit (the CV_32FC3 frame is ToFloatBgr of
  // an 8-bit image, as decoded PNG/JPEG/video frames are), and make the float
  // frames (and their pre-smoothed copies) only while a view is densified:
  // the window takes ~1/4 of the memory (1/9 for frames the depth stage had
  // smoothed), with bit-identical results. Other frames are held as they come.
  // While one view is densified, its neighbours' float frames are made one at
  // a time (PhotoconsistencyAccumulator), whatever this option says.
  // Cost: each neighbour's conversion and pre-smoothing is redone for every
  // view that uses it.
  bool compact_frames = true;
  // Views to process (sequence indices); empty: those `selection` picks.
  std::vector<int> views;
  // Which views get depth, densification and fusion when `views` is empty
  // (every frame is still read and serves as a neighbour): ReconstructionPlan.
  ViewSelectionOptions selection;
  // Where to write mesh.ply, mesh_raw.ply, grid.vdb, report.json, mesh_turntable.png (and depth/
  // when write_depth); empty: write nothing, only return the result.
  std::filesystem::path out_dir;
  bool write_depth = false;  // OUT/depth/<stem>.pfm and OUT/confidence/<stem>.pfm of the fused maps
  bool write_vdb = true;
  bool write_turntable = true;  // OUT/mesh_turntable.png: four shaded views of the final mesh
  // Previews for a person of this many views, evenly spread over the processed
  // ones (report.html shows them): OUT/preview/<stem>.png, the frame beside its
  // fused depth map (turbo), and, when densifying, OUT/edges/<stem>.png, the
  // dense stage's edges (§4.1: silhouette orange, texture blue), as
  // `lfrecon depth --stage dense` writes them. 0: none.
  int preview_views = 4;
  // Fields added to report.json (an object; e.g. the CLI's pose refinement figures), written with it once.
  nlohmann::json extra_report = nlohmann::json::object();

  void Check() const;  // throws OptionError
};


// The voxel size the pipeline uses for V and the options (voxel_size, or V's longest side / voxel_divisions).
double PipelineVoxelSize(const BoundingBox& volume, const PipelineOptions& options);

// The fusion grid's options as the pipeline sets them up for V: voxel size, and
// σ_s of dense maps (dense_sigma_s) when densifying. Throws OptionError.
FusionOptions PipelineFusionOptions(const PipelineOptions& options, const BoundingBox& volume);

}  // namespace lfrecon
