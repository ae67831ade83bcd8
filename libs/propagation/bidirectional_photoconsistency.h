#pragma once
// Bidirectional photoconsistency (paper §4.1, BRIEF §1.3). For a pixel p with
// depth d_p, θ(p) is the direction of the image gradient (eq. 8); three pixels
// on each side of p along θ(p) (f+ on the positive side, f− on the negative
// one) are projected through the plane fronto-parallel to the reference view
// at depth d_p into every view within 5°, and compared with what that view
// sees there (g+, g−): ρ(f±, g±) = exp(−‖f± − g±‖² / (2σ_p²)) (eq. 9), and
// C+(p), C−(p) are the averages of ρ over the views. Both sides of a texture
// edge move with p, so both are consistent; at a silhouette only the object's
// side is. |C+ − C−| / (C+ + C−) > 0.3 marks a silhouette edge (Fig. 4).
//
// Our choices where the paper is open:
//  * ‖f − g‖² is the squared colour difference *per sample pixel* (summed over
//    BGR, averaged over the 3 samples of a side), so σ_p = σ_c means what σ_c
//    means in eq. 4 (one pixel's colour difference). A sum over the 3 samples
//    would make the 3-sample patch three times stricter than eq. 4 and let
//    image noise alone push ρ towards 0.
//  * The samples lie at 1, 2, 3 × sample_step_px from p along θ(p), bilinearly
//    interpolated, in images optionally pre-smoothed by presmooth_sigma.
//  * A side whose samples leave the reference image has C = 0; a view where a
//    side's projection leaves that view does not count in that side's average.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "depth/depth_map.h"
#include "depth/gradient_depth_estimator.h"
#include "geometry/pinhole_view.h"
#include "util/scratch_pool.h"

namespace lfrecon {

struct PhotoconsistencyOptions {
  // σ_p of ρ (eq. 9); the paper sets σ_p = σ_c = 0.025 (eq. 4).
  double sigma_p = 0.025;
  // Weight of the chroma part of ‖f − g‖² (ours; propagation/colour_difference.h):
  // 1 is the paper's test. 0.5: JPEG and video store chroma at half
  // resolution, so on parts one or two pixels wide it is the background's;
  // on the six-set quality table (docs/benchmarks.md) thin recall +0.02 to
  // +0.04 on the JPEG sets, F@5 within 0.002 of 1 on the rest.
  double chroma_weight = 0.5;
  // Pixels sampled on each side of p along θ(p) (§4.1: three).
  int samples_per_side = 3;
  // Distance between consecutive samples along θ(p), pixels (ours: 1, adjacent pixels).
  double sample_step_px = 1.0;
  // Views within this angle of the reference take part (§4.1: 5°).
  double max_view_angle_deg = 5.0;
  // Use at most this many of the views within max_view_angle_deg, spread
  // evenly over them by angle (ours, for speed; 0: all of them, as §4.1).
  int max_views = 0;
  // |C+ − C−| / (C+ + C−) above this marks a silhouette edge (Fig. 4: 0.3).
  double silhouette_ratio = 0.3;
  // σ (pixels) of a Gaussian applied to the reference and neighbour images
  // before sampling (ours; 0: the frames as they are). When > 0 and a
  // ViewImage carries `smoothed` (the depth stage fills it with the same
  // 0.65 px Gaussian), that image is used instead of smoothing again.
  double presmooth_sigma = 0.65;
  // Also compute C0(p) (ours, on by default; PaperPropagationOptions turns it
  // off): ρ of three samples *along* the edge (p and p ± one step
  // perpendicular to θ(p)) through the same plane. On a part one or two
  // pixels wide both sides of the edge are background, so C+ and C− are low
  // at the part's own depth while C0 is high; the propagation
  // (DepthPropagator) then keeps a foreground pixel's depth and side after
  // the filter, with confidence C0, where C0 beats max(C+, C−) by the
  // silhouette ratio (it is not fed to the filter: as a source it spread the
  // part over its neighbours). Quality table (docs/benchmarks.md,
  // "Consistency along the edge"): thin-degraded F@5 0.659 -> 0.956 (thin
  // recall 0.482 -> 0.903), figurines thin recall 0.854 -> 0.874,
  // figurines-noisy 0.786 -> 0.818, no set's F@5 lower; a degraded rod seen
  // from a fifth of a loop is thickened by its noisy depths
  // (tests/pipeline/thin_rod_test.cc: P@5 0.902, P@10 1.000).
  bool centre_consistency = true;
  // Eight pixels at once with AVX2 where the CPU has it (ours, for speed);
  // false: one pixel at a time. Both paths do the same float operations in
  // the same order, so their C± are bit for bit the same (tested).
  bool simd = true;

  void Check() const;  // throws OptionError
};

// What a pixel's edge is, from its silhouette ratio.
enum class EdgeClass : std::uint8_t {
  kNone = 0,        // no depth, or no gradient direction: not evaluated
  kTexture = 1,     // ratio <= silhouette_ratio: both sides consistent
  kSilhouette = 2,  // ratio > silhouette_ratio: only one side consistent
  kUnresolved = 3,  // C+ + C− == 0: neither side consistent at this depth (or no view saw it)
};

// Per-pixel result of the photoconsistency stage, all the size of the reference image.
struct EdgeConsistency {
  cv::Mat c_plus;     // CV_32F, C+(p) in [0, 1]; 0 where not evaluated
  cv::Mat c_minus;    // CV_32F, C−(p) in [0, 1]; 0 where not evaluated
  cv::Mat direction;  // CV_32FC2, unit image-gradient direction (cos θ, sin θ); (0, 0) where none
  cv::Mat evaluated;  // CV_8U, 255 where C± were computed (the pixel has depth and a gradient direction)
  cv::Mat c_centre;   // CV_32F, C0(p) (PhotoconsistencyOptions::centre_consistency); empty when off

  // |C+ − C−| / (C+ + C−) (CV_32F; 0 where not evaluated or C+ + C− == 0).
  cv::Mat SilhouetteRatio() const;
  // EdgeClass per pixel (CV_8U) for the given ratio threshold.
  cv::Mat Classify(double silhouette_ratio) const;
};

class BidirectionalPhotoconsistency {
 public:
  explicit BidirectionalPhotoconsistency(const PhotoconsistencyOptions& options);

  // C± at every pixel of `depth` with depth > 0 and a non-zero image gradient.
  // `neighbors` may hold any views (and null pointers); those beyond
  // max_view_angle_deg or at the reference's own centre are ignored. Never
  // throws on degenerate input: an empty depth map, no edges or no usable
  // neighbour give all-zero maps.
  EdgeConsistency Compute(const ViewImage& reference, const std::vector<const ViewImage*>& neighbors,
                          const DepthMap& depth) const;

  // The neighbours Compute would use, as indices into `neighbors`, in the
  // order it adds them up (by increasing angle, thinned to max_views): the
  // order in which to feed them to PhotoconsistencyAccumulator::Add. Only the
  // views are read; a null pointer is skipped.
  std::vector<int> SelectNeighbors(const PinholeView& reference, const std::vector<const PinholeView*>& neighbors) const;

  const PhotoconsistencyOptions& options() const { return options_; }

 private:
  PhotoconsistencyOptions options_;
};

// Compute, one neighbour at a time, so that a caller needs only one
// neighbour's frame (and its smoothed copy) at once: Begin(reference, depth),
// Add(neighbour) for each neighbour in the order of SelectNeighbors, Finish().
// Each pixel adds up ρ over the neighbours in the order they are added, so with
// that order the result is bit for bit Compute's. Add ignores a null, empty or
// non-CV_32FC3 neighbour, one beyond max_view_angle_deg and the reference
// itself (none of them counts towards max_views here: select first).
class PhotoconsistencyAccumulator {
 public:
  explicit PhotoconsistencyAccumulator(const PhotoconsistencyOptions& options);

  // Starts over for `reference` (its frame is read only here: its smoothed
  // samples are kept for the pixels to evaluate) and the depths of `depth`.
  void Begin(const ViewImage& reference, const DepthMap& depth);
  // Adds one neighbour's ρ to the sums; its frame is not kept.
  void Add(const ViewImage& neighbor);
  // C± of what was added; the accumulator is empty afterwards.
  EdgeConsistency Finish();

  int neighbors_added() const { return added_; }

 private:
  // Pixels to evaluate (depth and a gradient direction), as a structure of
  // arrays padded to whole blocks of kLanes; the padding has no valid side.
  static constexpr int kLanes = 8;
  struct Neighbor;  // what Add needs of one neighbour
  void AddPixel(std::size_t i, const Neighbor& nb);
  void AddBlock(std::size_t block, const Neighbor& nb);

  PhotoconsistencyOptions options_;
  PinholeView reference_view_;
  EdgeConsistency out_;
  std::size_t num_pixels_ = 0;
  std::vector<int> row_, col_;
  std::vector<float> d_, px_, py_;   // depth, pixel centre
  std::vector<float> sx_, sy_;       // one sample step along θ(p)
  // 0 or -1 (all bits set: a lane mask): f+ / f− inside the reference, and
  // C0's samples (centre_consistency).
  std::vector<std::int32_t> side_ok_[2], centre_ok_;
  std::vector<float> sum_rho_[2], count_[2], sum_centre_, count_centre_;
  // The reference's samples: f+ then f− (3·samples_per_side BGR each), then
  // C0's 3; value v of pixel i at ((i / kLanes)·values + v)·kLanes + i % kLanes.
  // 36 MiB for a 720p view: a block from a ScratchPool, kept for the next view.
  ScratchPool::Lease samples_lease_;
  float* samples_ = nullptr;
  bool valid_ = false;
  int added_ = 0;
};

// Unit gradient direction (cos θ, sin θ) of the grey image (eq. 8), CV_32FC2,
// with the same 3×3 Sobel / 8 derivative that the depth stage thresholds;
// (0, 0) where the gradient vanishes.
cv::Mat GradientDirection(const cv::Mat& image_bgr);

}  // namespace lfrecon
