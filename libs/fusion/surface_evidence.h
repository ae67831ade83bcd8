#pragma once
// One view's evidence about voxels (BRIEF §1.5, eqs. 11-13), from a compact
// copy of its depth map. The fusion keeps one CompactDepthView per integrated
// view so that voxels activated later can be back-filled with exactly the
// evidence they would have received had they been active from the start
// (order independence). Direct updates and back-fill both go through
// SurfaceEvidence on the same quantised data, so they agree bit for bit —
// unless the store is over its memory budget and has coarsened the view
// (CompactDepthView::Coarsened, FusionOptions::store_budget_bytes).
#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include "depth/depth_map.h"
#include "fusion/fusion_options.h"
#include "geometry/pinhole_view.h"
#include "geometry/triangle_mesh.h"

namespace lfrecon {

// A depth map quantised to 4 bytes per pixel: planar depth as 16 bits over the
// view's depth range of V (resolution (far - near) / 65533, ~14 µm for a 0.9 m
// range), confidence as 8 bits, the label as 8 bits.
//  - foreground (label kForeground, or, when the map has no labels, depth > 0
//    with its point inside V): the depth, clamped to [near, far];
//  - background with a depth beyond V, or with depth 0 (nothing hit / sky): the
//    whole ray through V is free;
//  - background nearer than V's nearest point: it occludes all of V — kept as "none";
//  - no depth (0) without a background label, or confidence <= 0: none.
//
// A coarsened view (block() > 1) keeps one Pixel per block x block pixels
// (see Coarsened); at(row, col) then addresses blocks, and SurfaceEvidence
// samples the block that contains a voxel's projection.
class CompactDepthView {
 public:
  struct Pixel {
    std::uint16_t depth = 0;  // 0 none, kBeyond: background behind V, else 1 + quantised depth
    std::uint8_t confidence = 0;
    std::uint8_t label = 0;  // DepthLabel
  };
  static constexpr std::uint16_t kBeyond = 65535;

  CompactDepthView() = default;
  CompactDepthView(const PinholeView& view, const DepthMap& depth, const BoundingBox& volume);

  const PinholeView& view() const { return view_; }
  int width() const { return view_.width; }
  int height() const { return view_.height; }
  double near_depth() const { return near_; }
  double far_depth() const { return far_; }
  // Pixels (block x block of the view's pixels each) per row and column of the stored grid.
  int block() const { return block_; }
  int grid_width() const { return grid_width_; }
  int grid_height() const { return grid_height_; }
  const Pixel& at(int row, int col) const { return pixels_[static_cast<std::size_t>(row) * grid_width_ + col]; }
  // Decoded depth (metres; +infinity for kBeyond, 0 for none) and confidence in [0, 1].
  double Depth(const Pixel& p) const {
    if (p.depth == 0) return 0;
    if (p.depth == kBeyond) return std::numeric_limits<double>::infinity();
    return near_ + (p.depth - 1) * step_;
  }
  static double Confidence(const Pixel& p) { return p.confidence / 255.0; }
  static DepthLabel Label(const Pixel& p) { return static_cast<DepthLabel>(p.label); }

  int CountForeground() const;  // stored pixels (blocks when coarsened)
  std::size_t MemoryBytes() const {
    return pixels_.capacity() * sizeof(Pixel) + tile_max_.capacity() * sizeof(std::uint16_t) + sizeof(*this);
  }

  // The stored grid in tiles of kTile x kTile: per tile the largest depth
  // code of its pixels (0: none has a depth; kBeyond: some background lies
  // beyond V). A voxel farther than that depth plus the band is occluded
  // wherever it projects into the tile (SurfaceEvidence skips such blocks).
  static constexpr int kTile = 8;
  std::uint16_t TileMaxCode(int tile_row, int tile_col) const {
    return tile_max_[static_cast<std::size_t>(tile_row) * tiles_wide_ + tile_col];
  }
  bool HasTiles() const { return !tile_max_.empty(); }

  // The same view with blocks of 2x2 stored pixels merged into one (block()
  // doubles, memory / 4), for the store's memory budget. A merged block is
  // conservative for free space, so thin features are not carved by it:
  //  - any foreground pixel: foreground at the *nearest* foreground depth
  //    (voxels in front of it are free, as they are for every pixel of the
  //    block; voxels behind it within the band get eq. 11, deeper ones are
  //    occluded), confidence the mean over the foreground pixels within
  //    `band` (metres) of that depth;
  //  - else any background pixel: background at the nearest background depth
  //    (kBeyond only when all are), confidence their mean;
  //  - else none.
  // Cost: around silhouettes the object is dilated by up to a block (a voxel
  // just outside it, at the surface's depth, gets positive evidence instead
  // of free space), and depth within a block is its front-most one.
  CompactDepthView Coarsened(double band) const;

 private:
  PinholeView view_;
  double near_ = 0, far_ = 0, step_ = 0;
  int block_ = 1, grid_width_ = 0, grid_height_ = 0;
  std::vector<Pixel> pixels_;
  int tiles_wide_ = 0;
  std::vector<std::uint16_t> tile_max_;
  void ComputeTiles();
};

// Precomputed per view: the projection rows and option constants.
class SurfaceEvidence {
 public:
  SurfaceEvidence(const CompactDepthView& view, const FusionOptions& options);
  // For `view` with the options of `other`, whose tables it copies instead of
  // recomputing them (~500 exp/log each: back-fill builds one per stored view
  // for every integrated view).
  SurfaceEvidence(const CompactDepthView& view, const SurfaceEvidence& other);

  // log P_i(v ∈ S | c_{v,i}) for the world point x (a voxel centre). Returns
  // false when view i says nothing about x: x is behind the camera or outside
  // the image, its pixel has no depth, or x is occluded (more than the band
  // behind a foreground depth, or behind a background surface). Optionally
  // returns c_{v,i}.
  bool LogProbability(const Eigen::Vector3d& x, float* log_p, double* c = nullptr) const;

  // Eqs. 12-13 for a confidence c, clamped to [ε, 1-ε].
  static double Probability(double c, double sigma_s, double clamp);

  // The voxel centres of a block of 8 x 8 x 8 voxels (an OpenVDB leaf):
  // voxel n = 64 i + 8 j + k (OpenVDB's order in a leaf) has its centre at
  // (x[i], y[j], z[k]).
  static constexpr int kBlockDim = 8;
  static constexpr int kBlockVoxels = kBlockDim * kBlockDim * kBlockDim;
  struct BlockCentres {
    double x[kBlockDim], y[kBlockDim], z[kBlockDim];
  };
  // LogProbability of the voxels of a block whose bit is set in `active`
  // (bit n % 64 of word n / 64): log P into log_p[n] and bit n set in `has`
  // where the view says something. The same value, bit for bit, as
  // LogProbability of each centre; cheaper per voxel, as the projection is
  // summed from per-axis terms.
  void BlockLogProbability(const BlockCentres& centres, const std::uint64_t active[kBlockDim],
                           float log_p[kBlockVoxels], std::uint64_t has[kBlockDim]) const;

  const CompactDepthView& view() const { return *view_; }

 private:
  bool Sample(double u, double v, DepthLabel* label, double* depth, double* confidence) const;
  // K (R x + t), summed in one fixed order (that of Eigen's 3x3 product with
  // SSE2) which BlockLogProbability reproduces from per-axis terms.
  Eigen::Vector3d Project(const Eigen::Vector3d& x) const;
  // BlockLogProbability voxel by voxel.
  void BlockByVoxel(const BlockCentres& centres, const std::uint64_t active[kBlockDim], float log_p[kBlockVoxels],
                    std::uint64_t has[kBlockDim]) const;
  // LogProbability from the projection h = K (R x + t).
  bool FromProjection(double h0, double h1, double z, float* log_p, double* c_out) const;
  bool NearestLogP(double h0, double h1, double z, float* log_p) const;
  // Eqs. 12-13 as log, clamped, for the c of eq. 11 or of free space.
  float LogPOfC(double c) const;

  const CompactDepthView* view_;
  Eigen::Matrix3d P_;  // K R
  Eigen::Vector3d p_;  // K t
  double sigma_v_, band_, margin_;
  bool carve_front_;
  double two_over_s2_;
  double log_clamp_lo_, log_clamp_hi_;
  bool bilinear_;
  // Per confidence byte (nearest sampling; bilinear confidences are not
  // bytes): the free-space log P (c = -confidence), and the squared distance
  // |d_{v,i} - d_i|^2 below which eq. 11's c is so large that log P is
  // clamped to log(1-ε) (with a margin far above rounding; -1: never).
  float free_log_p_[256];
  double clamped_within_sq_[256];
};

}  // namespace lfrecon
