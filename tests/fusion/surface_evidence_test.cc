// SurfaceEvidence's fast paths (per-byte tables, the clamp shortcut, the
// per-leaf projection of BlockLogProbability) give exactly the log P of the
// plain formulas of eqs. 11-13, bit for bit, on every kind of voxel.
#include "fusion/surface_evidence.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>

#include "fusion_test_rig.h"

namespace lfrecon {
namespace {

enum Kind { kNone, kFree, kBandClamped, kBandShoulder, kKinds };

// log P as SurfaceEvidence computed it before its fast paths (nearest sampling):
// projection by Eigen, then eqs. 11-13 in double.
bool ReferenceLogP(const CompactDepthView& m, const FusionOptions& o, const Eigen::Vector3d& x, float* log_p,
                   Kind* kind) {
  *kind = kNone;
  const PinholeView& view = m.view();
  const Eigen::Matrix3d P = view.K * view.R;
  const Eigen::Vector3d p = view.K * view.t;
  const Eigen::Vector3d h = P * x + p;
  const double z = h.z();
  if (!(z > 1e-9)) return false;
  double u = h.x() / z, v = h.y() / z;
  if (!(u >= 0 && v >= 0 && u < m.width() && v < m.height())) return false;
  if (m.block() > 1) {
    u /= m.block();
    v /= m.block();
  }
  const CompactDepthView::Pixel& px = m.at(static_cast<int>(v), static_cast<int>(u));
  if (px.depth == 0) return false;
  const double d = m.Depth(px), conf = CompactDepthView::Confidence(px);
  if (!(conf > 0)) return false;
  const double sigma_v = o.SigmaV();
  double c;
  if (CompactDepthView::Label(px) == DepthLabel::kForeground) {
    const double delta = z - d;
    if (delta > o.BandHalfWidth()) return false;
    if (o.free_space_margin >= 0 && delta < -o.free_space_margin * sigma_v) {
      c = -conf;
    } else {
      c = conf * std::exp(-delta * delta / (2.0 * sigma_v * sigma_v));
    }
  } else {
    if (z > d) return false;
    c = -conf;
  }
  const double a = -(2.0 / (o.sigma_s * o.sigma_s)) * c;
  const double lp = a > 0 ? -(a + std::log1p(std::exp(-a))) : -std::log1p(std::exp(a));
  const double hi = std::log1p(-o.probability_clamp);
  *log_p = static_cast<float>(std::clamp(lp, std::log(o.probability_clamp), hi));
  *kind = c < 0 ? kFree : lp >= hi ? kBandClamped : kBandShoulder;
  return true;
}

bool SameBits(float a, float b) { return std::memcmp(&a, &b, sizeof(float)) == 0; }

struct Rig {
  PinholeView view = testing::LookAtView({0, -1, 0}, {0, 0, 0}, 80, 60, 50);
  BoundingBox volume = testing::Box(Eigen::Vector3d::Constant(-0.25), Eigen::Vector3d::Constant(0.25));
  DepthMap depth{60, 80};

  // Foreground near depth 1 with random confidence, background (at 2 m or
  // beyond V) and holes.
  explicit Rig(unsigned seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<double> uni(0, 1);
    for (int r = 0; r < depth.depth.rows; ++r)
      for (int c = 0; c < depth.depth.cols; ++c) {
        const double t = uni(rng);
        float d = 0, conf = static_cast<float>(uni(rng));
        DepthLabel label = DepthLabel::kForeground;
        if (t < 0.6) {
          d = static_cast<float>(0.95 + 0.1 * uni(rng));
        } else if (t < 0.9) {
          label = DepthLabel::kBackground;
          d = t < 0.75 ? 0.0f : 2.0f;
        } else {
          conf = 0;  // none
        }
        depth.depth.at<float>(r, c) = d;
        depth.confidence.at<float>(r, c) = conf;
        depth.label.at<std::uint8_t>(r, c) = static_cast<std::uint8_t>(label);
      }
  }
};

FusionOptions Options(const BoundingBox& volume, double clamp) {
  FusionOptions fo;
  fo.volume = volume;
  fo.voxel_size = 0.004;
  fo.sigma_s = 0.15;
  fo.probability_clamp = clamp;
  return fo;
}

TEST(SurfaceEvidence, LogProbabilityMatchesThePlainFormulasBitForBit) {
  for (double clamp : {0.03, 1e-6}) {
    const Rig rig(7);
    const FusionOptions fo = Options(rig.volume, clamp);
    for (int coarsen = 0; coarsen <= 1; ++coarsen) {
      CompactDepthView cv(rig.view, rig.depth, rig.volume);
      if (coarsen) cv = cv.Coarsened(fo.BandHalfWidth());
      const SurfaceEvidence ev(cv, fo);
      std::mt19937 rng(11);
      std::uniform_real_distribution<double> px(-2, 82), py(-2, 62), pz(0.9, 1.1), far(0.1, 2.5);
      int kinds[kKinds] = {};
      for (int n = 0; n < 200000; ++n) {
        const Eigen::Vector3d x = rig.view.Unproject({px(rng), py(rng)}, n % 4 ? pz(rng) : far(rng));
        float want = 0, got = 0;
        Kind kind;
        const bool has_want = ReferenceLogP(cv, fo, x, &want, &kind);
        ++kinds[kind];
        ASSERT_EQ(ev.LogProbability(x, &got), has_want) << n;
        if (has_want) {
          ASSERT_TRUE(SameBits(got, want)) << n << ": " << got << " vs " << want << ", kind " << kind;
        }
      }
      // Every path was exercised.
      for (int k = 0; k < kKinds; ++k) EXPECT_GT(kinds[k], 1000) << "clamp " << clamp << ", kind " << k;
    }
  }
}

TEST(SurfaceEvidence, CopiedTablesGiveTheSameEvidence) {
  // Back-fill builds each view's evidence from another view's tables.
  const Rig rig(9);
  const PinholeView other_view = testing::LookAtView({0.3, -1, 0.2}, {0, 0, 0}, 64, 48, 40);
  const FusionOptions fo = Options(rig.volume, 0.03);
  const CompactDepthView cv(rig.view, rig.depth, rig.volume);
  DepthMap other_depth(48, 64);
  other_depth.depth.setTo(1.0f);
  const CompactDepthView other_cv(other_view, other_depth, rig.volume);
  const SurfaceEvidence other(other_cv, fo), own(cv, fo), copied(cv, other);
  std::mt19937 rng(2);
  std::uniform_real_distribution<double> px(0, 80), py(0, 60), pz(0.9, 1.1);
  int with_evidence = 0;
  for (int n = 0; n < 20000; ++n) {
    const Eigen::Vector3d x = rig.view.Unproject({px(rng), py(rng)}, pz(rng));
    float a = 0, b = 0;
    const bool has = own.LogProbability(x, &a);
    ASSERT_EQ(copied.LogProbability(x, &b), has);
    if (!has) continue;
    ASSERT_TRUE(SameBits(a, b)) << n;
    ++with_evidence;
  }
  EXPECT_GT(with_evidence, 10000);
}

TEST(SurfaceEvidence, BlockLogProbabilityMatchesLogProbabilityPerVoxel) {
  // Blocks across the image border, around the foreground depths and behind
  // them (occluded: skipped whole), in a view and in its coarsened copy.
  Rig rig(3);
  // A far foreground patch, so that blocks behind the near depths are seen there.
  for (int r = 20; r < 30; ++r)
    for (int c = 30; c < 45; ++c) rig.depth.depth.at<float>(r, c) = 1.15f;
  const FusionOptions fo = Options(rig.volume, 0.03);
  for (int coarsen = 0; coarsen <= 1; ++coarsen) {
  CompactDepthView cv(rig.view, rig.depth, rig.volume);
  if (coarsen) cv = cv.Coarsened(fo.BandHalfWidth());
  const SurfaceEvidence ev(cv, fo);
  std::mt19937_64 rng(5);
  const double s = fo.voxel_size;
  int voxels_with_evidence = 0;
  for (int trial = 0; trial < 1000; ++trial) {
    // A leaf around or behind the foreground depth (y ~ 0: depth ~1 from the camera at y = -1).
    const Eigen::Vector3i origin(static_cast<int>(rng() % 118), 50 + static_cast<int>(rng() % 68),
                                 static_cast<int>(rng() % 118));
    SurfaceEvidence::BlockCentres centres;
    for (int t = 0; t < SurfaceEvidence::kBlockDim; ++t) {
      centres.x[t] = fo.volume.min.x() + s * (origin.x() + t + 0.5);
      centres.y[t] = fo.volume.min.y() + s * (origin.y() + t + 0.5);
      centres.z[t] = fo.volume.min.z() + s * (origin.z() + t + 0.5);
    }
    std::uint64_t active[SurfaceEvidence::kBlockDim], has[SurfaceEvidence::kBlockDim];
    for (auto& w : active) w = trial % 3 == 0 ? rng() & rng() & rng() & rng() : trial % 3 == 1 ? ~std::uint64_t{0} : rng();
    float lp[SurfaceEvidence::kBlockVoxels];
    ev.BlockLogProbability(centres, active, lp, has);
    for (int n = 0; n < SurfaceEvidence::kBlockVoxels; ++n) {
      const int i = n / 64, j = (n / 8) % 8, k = n % 8;
      const bool on = (active[i] >> (n % 64)) & 1, got = (has[i] >> (n % 64)) & 1;
      float want = 0;
      const bool has_want = on && ev.LogProbability({centres.x[i], centres.y[j], centres.z[k]}, &want);
      ASSERT_EQ(got, has_want) << "trial " << trial << " voxel " << n;
      if (has_want) {
        ASSERT_TRUE(SameBits(lp[n], want)) << "trial " << trial << " voxel " << n;
        ++voxels_with_evidence;
      }
    }
  }
  EXPECT_GT(voxels_with_evidence, 20000);
  }
}

}  // namespace
}  // namespace lfrecon
