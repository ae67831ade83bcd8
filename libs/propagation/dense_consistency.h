#pragma once
// Photometric check of a dense depth map (ours; after §4.2): every foreground
// pixel's propagated depth is projected into the neighbours with the widest
// baselines and its colour compared with theirs, ρ = exp(−‖f − g‖² / (2σ_p²))
// as in eq. 9. Propagation fills low-texture space beyond an object's
// silhouette with the object's depth (a "halo": on the figurines ~19 % of the
// pixels that see background get a foreground depth inside V, nearly all well
// in front of the truth); where what lies behind has any texture, the colours
// there disagree between views at that depth, while a correct depth agrees.
// Views on either side of the reference are averaged separately and the
// better side counts, so a pixel next to an occluding edge is not penalised
// for the views in which it is hidden.
#include <vector>

#include "depth/depth_map.h"
#include "depth/gradient_depth_estimator.h"
#include "geometry/pinhole_view.h"

namespace lfrecon {

struct DenseConsistencyOptions {
  // σ_p of ρ (eq. 9; the paper's σ_p = σ_c = 0.025), on the squared
  // difference of the patches' mean colours summed over BGR. 0.05 keeps more
  // of a finely textured object (test fixture: 99.9 % against 94.6 %) but on
  // the figurines gains less (mesh F@5mm / thin@5mm 0.657 / 0.811 against
  // 0.668 / 0.851).
  double sigma = 0.025;
  // Neighbours used: the `views` within max_view_angle_deg farthest from the
  // reference (widest baselines, largest parallax for a wrong depth), split
  // evenly between its two sides where possible.
  // 0: no check.
  int views = 4;
  // ρ compares the mean colours of (2r+1)² patches: the reference's around
  // the pixel, the neighbour's (box-filtered once per neighbour) sampled where
  // the pixel's centre lands through the plane fronto-parallel to the
  // reference at its depth (as §4.1 maps its samples; at ≤ 5° that plane's
  // mapping is locally a translation): the mean keeps image noise from rejecting
  // correct depths on flat colours (single pixels of the synthetic frames,
  // noise σ 0.01, give ρ ≈ 0.62 on a flat panel), while a halo's depth, tens
  // of pixels off, still compares different texture.
  int patch_radius_px = 1;
  double max_view_angle_deg = 5.0;
  // A foreground pixel whose ρ is below this loses its depth (this view then
  // gives no evidence there). `lfrecon run` on the figurines, mesh.ply
  // F@5mm / thin recall@5mm: no check 0.652 / 0.786; this check 0.668 / 0.851;
  // synthetic demo unchanged (0.832 / 0.411 against 0.832 / 0.408).
  double rho_min = 0.6;
  // Texture test (ours): where the reference's (2r+1)² grey patch around the
  // pixel has texture (standard deviation >= ncc_texture_min), its zero-mean
  // normalised cross-correlation (ZNCC) with the neighbour's patch at the
  // mapped position must reach ncc_min on the better side, else the pixel
  // loses its depth as for a low ρ. Why: ρ compares mean colours, so a halo
  // over a background of even colour with fine texture (sand, carpet, a
  // table's grain) passes it wherever the mean colour is alike, while ZNCC
  // compares the texture itself and is blind to gain (exposure drift). ZNCC of
  // unrelated patches of 49 pixels is ~0 ± 0.14; of the same texture under
  // noise σ_n, about σ²/(σ² + σ_n²). Patches without texture (std below the
  // floor, noise-dominated) keep only the ρ test. ncc_radius_px 0: no texture test.
  // Off by default: on the figurines (120 of 480 views) radius 3 moved mesh
  // F@5mm (observed) 0.805 -> 0.807, P@5mm 0.732 -> 0.734 (dense false
  // foreground 8.6 % -> 8.4 % of the background pixels: the halo lies over
  // background with too little texture for it), for +20 ms per view; not
  // measured alone on the other sets.
  int ncc_radius_px = 0;
  double ncc_min = 0.3;
  double ncc_texture_min = 0.02;  // grey levels in [0, 1]

  void Check() const;  // throws OptionError
};

// Begin(reference, dense), Add(neighbour) for each of SelectNeighbors' views
// (in any order: sums per side), Finish(): per pixel the better side's mean ρ
// (0 where the texture test fails),
// CV_32F, −1 where not evaluated (no foreground depth, or no neighbour saw the
// point). Images are read from `smoothed` when present, else `image` (CV_32FC3).
class DenseConsistencyAccumulator {
 public:
  explicit DenseConsistencyAccumulator(const DenseConsistencyOptions& options);

  // The neighbours to add, as indices into `neighbors` (null pointers skipped).
  std::vector<int> SelectNeighbors(const PinholeView& reference,
                                   const std::vector<const PinholeView*>& neighbors) const;

  // Pixels where `own` (optional CV_32F depth map, e.g. the filtered sparse
  // map the dense one came from) has a depth are not checked: the depth stage
  // and §4.1 already matched them, and on thin parts (a few pixels wide, whose
  // pixels mix object and background colours) a single-pixel comparison would
  // wrongly reject them.
  void Begin(const ViewImage& reference, const DepthMap& dense, const cv::Mat& own = cv::Mat());
  void Add(const ViewImage& neighbor);
  cv::Mat Finish();

 private:
  struct Pixel {
    int row = 0, col = 0;
    float d = 0;
    float colour[3] = {0, 0, 0};  // the reference's patch mean
    float sum[2] = {0, 0};
    int count[2] = {0, 0};
    bool textured = false;   // the texture test applies
    float grey_mean = 0, grey_std = 0;  // of the reference's ZNCC patch
    float ncc_sum[2] = {0, 0};
    int ncc_count[2] = {0, 0};
  };
  DenseConsistencyOptions options_;
  PinholeView reference_view_;
  cv::Mat reference_grey_;  // CV_32F, for the texture test
  cv::Size size_;
  std::vector<Pixel> pixels_;
};

// Pixels where ρ (Finish's map) is evaluated and below rho_min lose their
// depth, confidence and label.
void ApplyDenseConsistency(const cv::Mat& rho, double rho_min, DepthMap* dense);

// The whole check on `dense` with the neighbours' frames at once.
void CheckDenseConsistency(const ViewImage& reference, const std::vector<const ViewImage*>& neighbors,
                           const DenseConsistencyOptions& options, DepthMap* dense, const cv::Mat& own = cv::Mat());

}  // namespace lfrecon
