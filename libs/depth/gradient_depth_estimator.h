#pragma once
// Depth from gradients (paper §3.1, BRIEF §1.1): per pixel with a strong image
// gradient, the 1-D optical flow along its epipolar line in neighbouring
// views, measured from the gradient of a 2×5 epipolar patch, gives its depth.
//
// Our choices where the paper is open (measured in docs/benchmarks.md):
//  * The shift of eq. 2-3 is computed as a least-squares fit over the patch's
//    columns, summed over the colour channels, and iterated (Gauss-Newton) at
//    the chosen reference point, so it converges instead of being one linear step.
//  * Patches are sampled from slightly smoothed frames (presmooth_sigma).
//  * Levels are not discarded: each view's estimate is kept with a weight equal
//    to its Fisher information on depth (gradient energy along ℓ times the
//    squared pixels-per-metre of that view), and the depth is their weighted
//    mean; a view whose match lies too far from the current prediction is an
//    outlier and is dropped. Far views thus sharpen the estimate, and pixels
//    whose edge is nearly parallel to ℓ (the aperture problem) get little weight.
#include <vector>

#include "depth/depth_map.h"
#include "geometry/pinhole_view.h"
#include "geometry/triangle_mesh.h"

namespace lfrecon {

struct GradientDepthOptions {
  // g: only pixels with ‖∇I‖ above it get a depth (§3.1). Gradient of the
  // grey image in [0, 1] per pixel (central differences).
  double gradient_threshold = 0.05;
  // Length of each row of the 2×5 patch s_ij (eq. 1).
  int patch_length = 5;
  // Parallel segments, one pixel apart, that the shift is fitted over (ours:
  // 1 is the paper's 2×5 patch; 3 adds the lines beside ℓ, which helps edges
  // nearly parallel to ℓ, the aperture problem).
  int patch_rows = 3;
  // σ_c of the colour term C^c (eq. 4).
  double sigma_c = 0.025;
  // Views within this angle of the reference view take part (§3.1: 5°).
  double max_view_angle_deg = 5.0;
  // Reference points (one pixel apart) sampled around the predicted match at
  // each level after the first (§3.1: "sample K reference points around").
  int refine_reference_points = 3;
  // Gauss-Newton steps of the shift at the chosen reference point (a third
  // step changed figurines accuracy by < 0.001 for ~10 % more instructions).
  int shift_iterations = 2;
  // The steps stop once one moves the match by less than this (pixels along
  // ℓ). At 0.1 the second step is skipped where the first moved the match by
  // < 0.1 px: sparse accuracy unchanged to 1e-3 on figurines, figurines-noisy
  // and a dense tabletop, sparse depth 7-10 % faster (docs/benchmarks.md,
  // "Shift tolerance"). Was 0.01.
  double shift_tolerance_px = 0.1;
  // Final fit: views whose match lies further than this from the fused
  // depth's prediction (pixels along ℓ) are dropped; σ of the scatter term
  // of the confidence (pixels).
  double inlier_pixels = 0.75;
  double sigma_match = 0.25;
  // A view's match further than this (pixels along ℓ) from the prediction is an outlier.
  double outlier_pixels = 1.5;
  // Depth search range of the first level (planar depth, metres). When
  // max_depth <= 0 it is derived from V: [0.5 × nearest corner, 20 × farthest corner].
  double min_depth = 0.0;
  double max_depth = 0.0;
  // Cap on the first level's reference points (K), for very wide ranges.
  int max_reference_points = 512;
  // Use every view within max_view_angle_deg (true) or only the nearest view
  // on each side (false; the paper's first level alone).
  bool use_hierarchy = true;
  // Levels after the first use, on each side, only views at least this many
  // times the angle of the previous level's view (1: every view within 5°).
  double level_angle_ratio = 1.0;
  // Thinning of dense sequences (ours): levels after the first use only views
  // on the hierarchy grid (ViewImage::on_grid; HierarchyGrid below spaces it
  // at least this many degrees apart along the sequence), and on each side
  // only views at least this many degrees (angle between viewing directions)
  // from the previous level's view; the farthest such view is always used.
  // The first level (nearest view on each side) is never thinned. At 0.5° a
  // sequence at least 0.5° apart (the figurines and the synthetic 480-frame
  // loop at 0.75°, the plane rig at exactly 0.5°) is unchanged, and one 0.12° apart (a 3000-frame loop) uses ~17 of the ~100
  // views within 5° (docs/benchmarks.md, last section). A level_angle_ratio > 1 thins compute too, but relative
  // to each reference, so the union of the frames that the pending views of a
  // stream need is still every frame within 5°: StreamingDepth cannot hold
  // fewer. 0: every view within max_view_angle_deg (the paper), whatever
  // their on_grid flags.
  double level_min_step_deg = 0.5;
  // σ (pixels) of a Gaussian applied to the images the patches sample (ours,
  // not the paper's): it removes the sub-pixel bias of bilinear sampling on
  // texture near the pixel scale, which otherwise dominates the error at 0.5 %
  // (synthetic plane and sphere tests; docs/benchmarks.md). ‖∇I‖ > g is still
  // tested on the unsmoothed frame.
  double presmooth_sigma = 0.65;
  // Edge pixels whose viewing ray misses V grown by this fraction of V's
  // largest extent on every side get no depth (ours, for speed; negative:
  // every edge pixel). Such a depth can be no point of V, and the
  // propagation's background channel (§4.2) reads depths around V's outline,
  // which the margin keeps. ~47 % of a 720p textured tabletop's edge pixels
  // miss V itself, 3.8 % miss it grown by a quarter (docs/benchmarks.md,
  // "Edge pixels whose ray misses V").
  double ray_margin = 0.25;
  // Only edge pixels whose ‖∇I‖ is at least this fraction of the larger of
  // their two neighbours' along the gradient direction (quantised to the 8
  // neighbours) get a depth (ours, for speed; 1: Canny's non-maximum
  // suppression; 0: every edge pixel, the paper). On texture at the pixel
  // scale most pixels pass g; those beside a maximum carry less information
  // on depth, and the propagation (§4.2) fills them.
  double gradient_peak_fraction = 0.0;
  // Levels stop for a pixel once its depth is settled outside V (ours, for
  // speed): when every depth whose match in the view just used lies within
  // outlier_pixels of the current one's is a point outside V. A later level
  // only accepts a match within outlier_pixels of the prediction, in a view
  // farther than this one, so the remaining levels would only refine a depth
  // that stays outside V (a pixel whose ray misses V, inside ray_margin:
  // at its first match). Its label stays background; the depth and the
  // confidence come from the views used so far, so they are coarser (they
  // still feed photo-consistency and the fusion's free space, where a
  // background depth only has to lie beyond the object). Labels changed on
  // < 0.01 % of pixels, sparse depth ~40 % faster (docs/benchmarks.md,
  // "Levels stop outside V"). false: every level for every pixel (the paper).
  bool settle_outside_volume = true;
  // The reference side of the patches (I_i's samples that the plane at the
  // reference point's depth maps onto I_j's patch) is sampled once per later
  // level's search, at the predicted depth, for all its reference points and
  // shift iterations, and once per 8 reference points of the first level's
  // scan (ours, for speed). Every such patch is centred on the pixel itself;
  // the depth changes only its shape (the plane homography's Jacobian), by
  // a negligible amount over a few pixels of the epipolar line. false:
  // sampled at each reference point's own depth.
  bool reuse_reference_patch = true;

  void Check() const;
};

// One view as the estimator sees it: undistorted geometry and a CV_32FC3 BGR
// image in [0, 1].
struct ViewImage {
  PinholeView view;
  cv::Mat image;
  // Filled by PrepareViewImage: once per frame by callers that reuse a view
  // for many references; computed on the fly when empty.
  cv::Mat smoothed;  // CV_32FC3, image smoothed by presmooth_sigma
  cv::Mat grey;      // CV_32F, grey levels of `smoothed`
  // On the hierarchy grid (see GradientDepthOptions::level_min_step_deg):
  // usable beyond the first level. Callers without a sequence leave it true.
  bool on_grid = true;
};

class GradientDepthEstimator {
 public:
  explicit GradientDepthEstimator(const GradientDepthOptions& options);

  // Sparse depth of `reference` from `neighbors` (any order; those beyond
  // max_view_angle_deg are ignored). Pixels without an estimate have depth 0.
  // Never throws for degenerate input: no usable neighbour, a blank frame or
  // coincident cameras give an empty map and a warning.
  DepthMap Estimate(const ViewImage& reference, const std::vector<const ViewImage*>& neighbors,
                    const BoundingBox& volume) const;

  const GradientDepthOptions& options() const { return options_; }

 private:
  GradientDepthOptions options_;
};

// The hierarchy grid of a sequence (in its order): view 0, then each view
// whose viewing direction is at least options.level_min_step_deg from that of
// the last view kept. Fixed for the whole sequence, so the pending views of a
// stream share their later-level views. All true when the step is 0 or the
// hierarchy is off.
std::vector<char> HierarchyGrid(const std::vector<PinholeView>& views, const GradientDepthOptions& options);

// The neighbours Estimate uses for `reference`, in the order it uses them
// (first level, then the later levels nearest first): indices into
// `neighbors`. Those beyond max_view_angle_deg or at the reference's centre
// are left out; on_grid[k] (empty: all true) says whether neighbour k is on
// the hierarchy grid. Selecting again among the selected views gives the same
// views, so a caller may pass Estimate only these.
std::vector<int> SelectHierarchyViews(const PinholeView& reference, const std::vector<const PinholeView*>& neighbors,
                                      const std::vector<char>& on_grid, const GradientDepthOptions& options);

// Fills view->smoothed and view->grey from view->image: Gaussian
// pre-smoothing with options.presmooth_sigma (none when 0), then grey levels.
void PrepareViewImage(ViewImage* view, const GradientDepthOptions& options);

// Grey-level gradient magnitude ‖∇I‖ per pixel (CV_32F), as the estimator thresholds it.
cv::Mat GradientMagnitude(const cv::Mat& image_bgr);

// GradientMagnitude with 0 at every pixel below `fraction` of the larger of
// its two neighbours along its gradient direction (see
// GradientDepthOptions::gradient_peak_fraction).
cv::Mat GradientPeaks(const cv::Mat& image_bgr, double fraction);

}  // namespace lfrecon
