#pragma once
// Photometric refinement of a dense depth map (ours; after §4.2): each
// foreground depth is searched again over a short range of inverse depths
// around its own, scoring each hypothesis by the zero-mean normalised
// cross-correlation (ZNCC) of the reference's grey (2r+1)² patch with the
// neighbours' patches where the plane through that depth maps it (tilted by
// the map's own slope where the map is planar, `slanted`; else fronto-
// parallel), averaged over the widest-baseline neighbours; a parabola
// through the best hypothesis and its two neighbours gives the new depth. Why:
// the depth from gradients measures each edge pixel's shift along one line
// and propagation interpolates between edges, so a dense depth is within 0.5 %
// of the truth at only ~63 % of the figurines' foreground pixels; a 2D patch
// compared over several baselines of up to 5° pins it to a fraction of a
// pixel of the widest one. ZNCC is blind to gain and offset (exposure drift).
// Depths whose best mean ZNCC is weak (no texture, occluded in most views) or
// lies at the range's end (the depth is farther off than the search) keep
// their value; a refined depth's confidence is raised to its ZNCC.
#include <vector>

#include "depth/depth_map.h"
#include "depth/gradient_depth_estimator.h"
#include "geometry/pinhole_view.h"

namespace lfrecon {

struct PhotometricRefinementOptions {
  // Neighbours compared: the `views` within max_view_angle_deg farthest from
  // the reference, split between its two sides. 0: no refinement.
  int views = 0;
  double max_view_angle_deg = 5.0;
  // ZNCC patch radius (pixels).
  int patch_radius_px = 2;
  // Hypotheses are `steps` on each side of the depth, `step_px` apart in
  // the shift they cause in the widest-baseline neighbour: ±3 px (a depth
  // farther off keeps its value). Figurines / figurines-noisy mesh F@2mm:
  // 4 x 0.5 px 0.747 / 0.699, 8 x 0.75 px 0.748 / 0.698, 3 x 1 px 0.749 /
  // 0.701. But a parabola through samples 0.75 px or more apart locks onto
  // them on fine texture (the unit test's 4 px wavelength: 3 x 1 px leaves
  // 87 % of the depths within 0.5 %, 4 x 0.75 px 79 % within 0.2 %), so
  // 0.6 px apart, five each side.
  int steps = 5;
  double step_px = 0.6;
  // The best hypothesis' mean ZNCC must reach this for the depth to change.
  double ncc_min = 0.5;
  // Reference patches with a grey standard deviation below this (noise-level
  // texture) are left alone.
  double texture_min = 0.01;
  // At least this many neighbours must see a pixel's patch.
  int min_views = 2;
  // A refined depth's confidence becomes at least its best mean ZNCC (>=
  // ncc_min). Why: propagated depths carry the filter's weak confidences
  // (mostly 0.002-0.05), so in fusion a refined, photo-consistent depth was
  // outvoted by its unrefined neighbours and the edges' noisier sparse depths.
  // Quality table (docs/benchmarks.md, "Dense depths searched again"):
  // figurines F@2mm 0.749 -> 0.782, F@5mm 0.926 -> 0.935; figurines-noisy
  // 0.699 -> 0.743, 0.914 -> 0.925; tabletop and occlusion-degraded within 0.001.
  bool raise_confidence = true;
  // Slanted patches: each pixel's plane follows the dense map's own inverse-
  // depth gradient (central differences over ±patch_radius_px, where both
  // ends are foreground within 10 % of the pixel's inverse depth and the
  // second difference is within 0.25 % of it: a planar stretch) instead of
  // being fronto-parallel (false). The inverse depth of a plane is affine in
  // the pixel, so a tilt only changes the patch's Jacobian. Quality table
  // (docs/benchmarks.md, "Slanted patches"): figurines F@2mm 0.782 -> 0.790,
  // figurines-noisy 0.743 -> 0.756, median error 0.85 -> 0.66 mm; F@5mm
  // within 0.001 on every set.
  bool slanted = true;
  // Use AVX2 where the CPU has it (8 pixels at once; the same float
  // operations in the same order as the scalar path, so the same depths).
  bool simd = true;

  void Check() const;  // throws OptionError
};

// Begin(reference, dense, neighbour views) gives the neighbours to add;
// Add(neighbour) for each of them (any order), Finish(&dense): one
// neighbour's frame at a time, so a caller need not hold them all at once.
// Reads each frame's PhotometricGrey (neighbor_views.h).
class PhotometricRefinementAccumulator {
 public:
  explicit PhotometricRefinementAccumulator(const PhotometricRefinementOptions& options);

  // Picks the `views` widest-baseline of `neighbors` (their widest baseline
  // sets the step) and returns their indices, the ones to Add (none when
  // nothing is to be refined). Pixels where `keep` (CV_8U or CV_32F,
  // optional) is non-zero are left alone.
  std::vector<int> Begin(const ViewImage& reference, const DepthMap& dense,
                         const std::vector<const PinholeView*>& neighbors, const cv::Mat& keep = cv::Mat());
  void Add(const ViewImage& neighbor);
  // Changes the depths (and confidences) of the refined pixels; returns how many changed.
  int Finish(DepthMap* dense);

 private:
  PhotometricRefinementOptions options_;
  PinholeView reference_view_;
  int rows_ = 0, cols_ = 0;
  double zeta_step_ = 0;             // inverse-depth step between hypotheses (1/m)
  std::vector<int> pixels_;          // row-major index of each refined pixel
  std::vector<float> zeta0_;         // its inverse depth
  std::vector<float> slope_x_, slope_y_;  // its inverse depth's change per pixel right and down (slanted)
  std::vector<float> ref_patch_;     // zero-mean reference patches, (2r+1)² per pixel, by blocks of 8 pixels
  std::vector<float> ref_norm_;      // sqrt of each patch's sum of squares (padded to whole blocks)
  std::vector<float> scores_;        // (2 steps + 1) ZNCC sums per pixel
  std::vector<int> counts_;          // neighbours that saw each pixel
};

// The accumulator over the usable `neighbors` at once.
int RefineDepthPhotometrically(const ViewImage& reference, const std::vector<const ViewImage*>& neighbors,
                               const PhotometricRefinementOptions& options, DepthMap* dense,
                               const cv::Mat& keep = cv::Mat());

}  // namespace lfrecon
