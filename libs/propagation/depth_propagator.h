#pragma once
// Edge-aware depth propagation (paper §4.2, BRIEF §1.4): turns the sparse,
// filtered depth of one view into a dense depth and confidence map.
//  1. Bidirectional photoconsistency C+/C− at every pixel with depth (§4.1,
//     bidirectional_photoconsistency.h).
//  2. Splat: the pixel next to p in the +θ(p) direction gets depth D(p) with
//     confidence C+(p), the one in the −θ(p) direction D(p) with C−(p); where
//     several edge pixels splat into one pixel the highest confidence wins;
//     edge pixels themselves keep D(p) with max(C+, C−).
//  3. Confidence-weighted joint edge-aware filtering with the frame as guide
//     (Lang et al. 2012 on the domain transform of Gastal & Oliveira 2011):
//     D' = filter(C ⊙ D) / filter(C) (eq. 10), done separately for the
//     foreground and the background depths; per pixel the side with the
//     larger filtered confidence C' wins, and the final confidence is
//     |C'_fg − C'_bg|.
// Output labels name the winning side; a foreground pixel whose interpolated
// depth lands just outside V stays foreground (relabelling it background
// would make fusion carve its whole ray).
//
// Our choices where the paper is open or where we measured better (figurines,
// 8 views, dense accuracy within 0.5 % over all ground-truth foreground
// pixels: the paper's reading 0.37, these defaults 0.58; per-choice figures in
// the benchmark notes), each an option so the paper's reading stays one call
// away (PaperPropagationOptions):
//  * kAffine model: a confidence-weighted least-squares plane in inverse depth
//    over the same edge-aware kernel instead of the weighted average of eq. 10;
//  * splat confidences are C± times the depth stage's own confidence;
//  * at silhouette edges only the consistent side is splatted, and the edge
//    pixel itself feeds the filter only through that splat, unless two such
//    pixels splat into each other (a part two pixels wide: they keep their depth);
//  * pixels that had a depth keep it where their side wins;
//  * the filter's spatial σ is a fraction of the image width, so maps at
//    1280×720 propagate as far (in the scene) as at 640×360; the guide is the
//    frame itself (guide_sigma = 0 measured best);
//  * values are filtered as offsets from a per-side reference (the
//    confidence-weighted mean), which keeps single-precision sums accurate
//    far from the edges; mathematically eq. 10 is unchanged;
//  * a pixel gets a depth only where the winning side's filtered confidence
//    exceeds min_filtered_confidence (the propagation did reach it).
// The filter: kConstant runs OpenCV ximgproc's DTFilter (dt_mode, one call
// over the 4 channels C_fg·D_fg, C_fg, C_bg·D_bg, C_bg). kAffine needs 11
// channels and DTFilter takes at most 4 per call (3 calls, each a full set of
// sweeps), so kAffine runs our DomainTransformFilter: the same recursive
// (DTF_RF) filter over all channels in one sweep, tested equal to OpenCV's
// DTF_RF to 2e-4.
#include <vector>

#include "depth/depth_map.h"
#include "depth/gradient_depth_estimator.h"
#include "geometry/triangle_mesh.h"
#include "propagation/bidirectional_photoconsistency.h"
#include "propagation/dense_consistency.h"
#include "propagation/photometric_refinement.h"

namespace lfrecon {

enum class DomainTransformMode {
  kNormalizedConvolution = 0,    // cv::ximgproc::DTF_NC (box kernels in the transformed domain)
  kInterpolatedConvolution = 1,  // DTF_IC
  kRecursive = 2,                // DTF_RF (exponential decay)
  kOwnRecursive = 3,             // DomainTransformFilter (ours): the RF filter on any number of channels
};

// What is propagated from the edges (ours: the paper's eq. 10 is kConstant).
enum class PropagationModel {
  // D' = filter(C ⊙ D) / filter(C) (eq. 10): a confidence-weighted average.
  kConstant = 0,
  // Foreground: a confidence-weighted least-squares affine fit a + b·x + c·y
  // of the value over the same edge-aware kernel (first-order normalized
  // convolution), evaluated at each pixel; with filter_inverse_depth it
  // reproduces planes exactly, where an average bends towards the edges'
  // mean. Background: as kConstant. Always runs on DomainTransformFilter (11 channels).
  kAffine = 1,
};

struct PropagationOptions {
  // §4.1: σ_p, 3 samples per side, views within 5°, silhouette ratio 0.3.
  PhotoconsistencyOptions photo;
  // Domain-transform filter (ours; the paper gives no values):
  // spatial σ as a fraction of the image width (0.06: 38 px at 640 px).
  double dt_sigma_spatial = 0.06;
  // Colour σ, in units of the guide's summed |ΔB| + |ΔG| + |ΔR| (colours in [0, 1]).
  double dt_sigma_color = 0.4;
  // The filter for kConstant (kAffine always runs DomainTransformFilter, the RF variant).
  DomainTransformMode dt_mode = DomainTransformMode::kNormalizedConvolution;
  int dt_iterations = 3;
  // σ (pixels) of a Gaussian that smooths the guide image (ours; 0: the frame itself).
  double guide_sigma = 0.0;
  PropagationModel model = PropagationModel::kAffine;
  // kAffine: ridge on the slopes, as the spread (pixels) of support it is
  // worth; keeps the fit near the average where the support is a line or a point.
  double affine_ridge_px = 0.25;
  // A pixel gets a depth only where max(C'_fg, C'_bg) exceeds this (ours).
  double min_filtered_confidence = 1e-4;
  // Multiply the splatted confidences by the depth stage's own confidence
  // (ours; false: C± alone, as the paper). Depths with confidence 0 then
  // take no part.
  bool weight_by_depth_confidence = true;
  // At a silhouette edge (ratio > photo.silhouette_ratio) splat only to the
  // consistent side (ours: §4.1 says the classification "helps decide on the
  // direction to which the depth is propagated"; false: both sides with their
  // C±, as §4.2 describes the splat).
  bool one_sided_silhouettes = true;
  // Silhouette edge pixels themselves give the filter nothing (ours): their
  // depth reaches it only through the splat on the consistent side, so it
  // cannot spread from the edge pixel to the occluded side (false: they
  // keep max(C+, C−), as §4.2).
  bool silhouette_pixels_splat_only = true;
  // ... except for two silhouette edge pixels of one label that splat into
  // each other (ours, on by default; PaperPropagationOptions turns it off):
  // the two sides of a part two pixels wide. Their splats cannot land (edge
  // pixels are not overwritten), so the part reaches the filter nowhere, the
  // background's depth wins over it and fusion carves it (thin-degraded, 8
  // views: 71 % of the rod's pixels come out background, 59 % with this on).
  // With it, such pixels keep their own depth with max(C+, C−), as §4.2 has
  // it. Quality table (docs/benchmarks.md, "two propagation fixes"): thin-degraded
  // F@5 0.634 -> 0.659, thin recall 0.452 -> 0.482; tabletop thin recall
  // 0.403 -> 0.397; the other four sets within 0.001 F@5. A broader version
  // (every silhouette whose target is any edge pixel, even of another label or
  // not pointing back) put a sheet beside the degraded rod of
  // tests/pipeline/thin_rod_test.cc (P@5 0.915, bound 0.95: a textured
  // background has edge pixels everywhere); this pair version gives 0.966.
  bool blocked_silhouettes_keep_depth = true;
  // After the filter, each foreground depth is checked against the frames of
  // the widest-baseline neighbours (dense_consistency.h; ours: views = 0 turns it off).
  DenseConsistencyOptions consistency;
  // Then each foreground depth that passed is searched again photometrically
  // (photometric_refinement.h; ours: views = 0 turns it off).
  PhotometricRefinementOptions refinement;
  // Pixels that had a depth keep it where their own side wins (ours; false:
  // every pixel takes the filtered depth D' of eq. 10, as the paper).
  bool keep_edge_depths = true;
  // A foreground edge pixel whose filtered background confidence beats its
  // foreground one only narrowly, by less than the silhouette ratio
  // (photo.silhouette_ratio, Fig. 4: C'_bg − C'_fg <= 0.3 (C'_bg + C'_fg)),
  // keeps its own depth and side (ours; false: the larger side always wins,
  // as §4.2). A part one or two pixels wide over a textured background: its
  // silhouette edge pixels feed the filter nothing, so both sides reach it
  // only faintly through the edge-aware filter, the background's slightly
  // larger share won, and the fusion carved the part from that view
  // (320x180 tabletop: the thin parts' depths within 5 mm, filtered 0.415 ->
  // dense 0.325 of their visible samples, thin_stage_bench). Such a pixel
  // gets confidence 1: at the dense maps' σ_s (0.15) any c above ~0.05 is a
  // full vote; with the depth stage's own confidence instead (mostly lower on
  // such parts) the tabletops' thin recall rose a third as much.
  // Quality table (docs/benchmarks.md, "Contested foreground edges"), thin
  // recall@5: tabletop 0.464 -> 0.526, tabletop-degraded 0.314 -> 0.479;
  // thin-degraded F@2 0.789 -> 0.880; no set's F@5 lower.
  bool keep_contested_foreground = true;
  // Filter inverse depth 1/D instead of D (ours): on a plane 1/D is affine in
  // the pixel coordinates, so averages of it stay on the plane.
  bool filter_inverse_depth = true;
  // kAffine (ours): a pixel the foreground fit reaches only by extrapolating
  // beyond its support (a halo beside a silhouette over plain background)
  // has a large Mahalanobis distance m from the support's weighted centroid
  // (in units of the support's own spread, floored at extrapolation_floor_px
  // so that a line of support is not a zero-width one). The foreground
  // confidence is multiplied by exp(-max(0, m - m0)² / 2), m0 this value
  // (2: within two spreads of the support nothing changes); 0: off. Pixels
  // with a foreground depth of their own are exempt. Whole pipeline
  // (tests/bench/quality_table.sh, docs/benchmarks.md), F@5mm / P@5mm:
  //   figurines        0.810 / 0.746 -> 0.825 / 0.771
  //   figurines-noisy  0.792 / 0.726 -> 0.804 / 0.747
  //   the four generated sets within 0.001, thin recall unchanged on all six.
  double extrapolation_m0 = 2.0;
  double extrapolation_floor_px = 2.0;

  void Check() const;  // throws OptionError
};

// The paper's §4.2 as written, for comparison: the constant model (eq. 10) on
// OpenCV's normalized-convolution DTFilter, both sides splatted with C±, edge
// pixels filtered like every other pixel, depth (not inverse depth) filtered,
// confidences C± alone. The filter's σs (which the paper does not give) stay ours.
PropagationOptions PaperPropagationOptions();

// Splatted maps before filtering (step 2), CV_32F each; 0 where nothing landed.
struct SplatMaps {
  cv::Mat depth_fg, confidence_fg;
  cv::Mat depth_bg, confidence_bg;
  cv::Mat edge_label;  // CV_8U: the DepthLabel of edge pixels (which keep their own depth), 0 elsewhere
  cv::Mat edge_depth;  // CV_32F: the depth of edge pixels, 0 elsewhere
  // CV_32F: C0 of edge pixels that keep their own depth and side after the
  // filter (PhotoconsistencyOptions::centre_consistency); empty when off.
  cv::Mat thin_confidence;

  // All maps rows × cols and zero.
  static SplatMaps Zeros(int rows, int cols);
};

struct DenseDepthResult {
  DepthMap dense;         // depth, confidence |C'_fg − C'_bg|, label (the winning side)
  EdgeConsistency edges;  // C± per edge pixel, for previews and diagnosis
  double seconds_photoconsistency = 0;
  double seconds_splat = 0;
  double seconds_filter = 0;
  double seconds_consistency = 0;
  double seconds_refinement = 0;
};

class DepthPropagator {
 public:
  explicit DepthPropagator(const PropagationOptions& options);

  // The whole of §4 for one view. `filtered` is the view's sparse (filtered)
  // depth map; its labels say which depths are foreground (pixels with depth
  // but label kNone are labelled from V). `neighbors`: views within 5° (others
  // are ignored). Defined for every input: no edges, no usable neighbour or
  // all-zero confidences give an empty map (depth 0, confidence 0, label kNone).
  DenseDepthResult Run(const ViewImage& reference, const std::vector<const ViewImage*>& neighbors,
                       const DepthMap& filtered, const BoundingBox& volume) const;

  // Whether Run can work on the input (a CV_32FC3 reference and a CV_32F
  // depth map of its size); otherwise Run gives an empty map.
  static bool ValidInput(const ViewImage& reference, const DepthMap& filtered);
  // Run's step 0: `filtered` with every depth that has no label labelled from V
  // (a depth whose point lies inside V is foreground). Needs ValidInput.
  static DepthMap LabelFromVolume(const PinholeView& view, const DepthMap& filtered, const BoundingBox& volume);
  // Step 2 alone: splats C± of `edges` around the depths of `filtered`.
  SplatMaps Splat(const DepthMap& filtered, const EdgeConsistency& edges) const;
  // Step 3 alone: eq. 10 on each side with `image` (CV_32FC3) as the guide, then the per-pixel choice.
  DepthMap Filter(const cv::Mat& image, const SplatMaps& splats) const;

  const PropagationOptions& options() const { return options_; }

 private:
  PropagationOptions options_;
};

// The call for the pipeline: the dense depth map of `reference` (§4) from its
// filtered sparse map and its neighbours' frames.
DepthMap DensifyDepth(const ViewImage& reference, const std::vector<const ViewImage*>& neighbors,
                      const DepthMap& filtered, const BoundingBox& volume, const PropagationOptions& options);

}  // namespace lfrecon
