#include "propagation/photometric_refinement.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#if defined(__x86_64__)
#include <immintrin.h>
#endif

#include "propagation/neighbor_views.h"
#include "util/error.h"

namespace lfrecon {

void PhotometricRefinementOptions::Check() const {
  LFRECON_CHECK_OPTION(views >= 0);
  LFRECON_CHECK_OPTION(max_view_angle_deg > 0 && max_view_angle_deg < 90);
  LFRECON_CHECK_OPTION(patch_radius_px >= 1 && patch_radius_px <= 5);
  LFRECON_CHECK_OPTION(steps >= 1 && steps <= 32);
  LFRECON_CHECK_OPTION(step_px > 0 && step_px <= 4);
  LFRECON_CHECK_OPTION(ncc_min >= -1 && ncc_min <= 1);
  LFRECON_CHECK_OPTION(texture_min >= 0);
  LFRECON_CHECK_OPTION(min_views >= 1);
}

PhotometricRefinementAccumulator::PhotometricRefinementAccumulator(const PhotometricRefinementOptions& options)
    : options_(options) {
  options_.Check();
}

std::vector<int> PhotometricRefinementAccumulator::Begin(const ViewImage& reference, const DepthMap& dense,
                                                         const std::vector<const PinholeView*>& neighbors,
                                                         const cv::Mat& keep) {
  reference_view_ = reference.view;
  rows_ = dense.depth.rows;
  cols_ = dense.depth.cols;
  pixels_.clear();
  zeta0_.clear();
  slope_x_.clear();
  slope_y_.clear();
  ref_patch_.clear();
  ref_norm_.clear();
  scores_.clear();
  counts_.clear();
  zeta_step_ = 0;
  if (options_.views <= 0 || dense.depth.empty() || reference.image.size() != dense.depth.size()) return {};
  const std::vector<int> chosen =
      WidestNeighbors(reference.view, neighbors, options_.max_view_angle_deg, options_.views);
  // The widest baseline's shift per unit inverse depth is about f·B.
  double baseline = 0;
  for (int j : chosen)
    baseline = std::max(baseline, (neighbors[static_cast<std::size_t>(j)]->Center() - reference.view.Center()).norm());
  if (baseline <= 0) return {};
  zeta_step_ = options_.step_px / (reference.view.K(0, 0) * baseline);

  cv::Mat keep_mask;
  if (!keep.empty() && keep.size() == dense.depth.size()) keep_mask = keep != 0;
  const cv::Mat grey = PhotometricGrey(reference);
  const int r = options_.patch_radius_px, n = (2 * r + 1) * (2 * r + 1);
  const float texture_min = static_cast<float>(options_.texture_min);
  std::vector<float> patch(static_cast<std::size_t>(n));
  for (int y = r; y < rows_ - r; ++y) {
    const float* d = dense.depth.ptr<float>(y);
    const std::uint8_t* l = dense.label.empty() ? nullptr : dense.label.ptr<std::uint8_t>(y);
    const std::uint8_t* kept = keep_mask.empty() ? nullptr : keep_mask.ptr<std::uint8_t>(y);
    for (int x = r; x < cols_ - r; ++x) {
      if (!(d[x] > 0) || (l && l[x] != static_cast<std::uint8_t>(DepthLabel::kForeground)) || (kept && kept[x])) continue;
      float mean = 0;
      int k = 0;
      for (int b = -r; b <= r; ++b) {
        const float* g = grey.ptr<float>(y + b) + x;
        for (int a = -r; a <= r; ++a) mean += patch[static_cast<std::size_t>(k++)] = g[a];
      }
      mean /= static_cast<float>(n);
      float ss = 0;
      for (float& v : patch) {
        v -= mean;
        ss += v * v;
      }
      if (std::sqrt(ss / static_cast<float>(n)) < texture_min || ss <= 0) continue;
      // Blocks of 8 pixels, each sample's 8 values side by side (the AVX2
      // path loads them at once); norms padded to whole blocks.
      const std::size_t i = pixels_.size();
      if (i % 8 == 0) {
        ref_patch_.resize(ref_patch_.size() + 8 * static_cast<std::size_t>(n), 0.0f);
        ref_norm_.resize(ref_norm_.size() + 8, 1.0f);
      }
      float* block = &ref_patch_[(i / 8) * 8 * static_cast<std::size_t>(n)];
      for (int s = 0; s < n; ++s) block[s * 8 + static_cast<int>(i % 8)] = patch[static_cast<std::size_t>(s)];
      ref_norm_[i] = std::sqrt(ss);
      pixels_.push_back(y * cols_ + x);
      zeta0_.push_back(1.0f / d[x]);
      float sx = 0, sy = 0;
      if (options_.slanted) {
        const float z0 = 1.0f / d[x];
        // The inverse depth at (x + dx, y + dy) when it is foreground and within 10 % of z0.
        auto zeta_at = [&](int dx, int dy, float* z) {
          const float v = dense.depth.at<float>(y + dy, x + dx);
          if (!(v > 0)) return false;
          if (!dense.label.empty() && dense.label.at<std::uint8_t>(y + dy, x + dx) !=
                                          static_cast<std::uint8_t>(DepthLabel::kForeground))
            return false;
          *z = 1.0f / v;
          return std::abs(*z - z0) <= 0.1f * z0;
        };
        // A slope only where the map is planar across the patch (its second
        // difference within 0.25 % of z0): noisy depths give no tilt.
        auto slope = [&](int dx, int dy) {
          float za, zb;
          if (!zeta_at(dx, dy, &za) || !zeta_at(-dx, -dy, &zb) || std::abs(za + zb - 2 * z0) > 0.0025f * z0) return 0.0f;
          return (za - zb) / static_cast<float>(2 * r);
        };
        sx = slope(r, 0);
        sy = slope(0, r);
      }
      slope_x_.push_back(sx);
      slope_y_.push_back(sy);
    }
  }
  scores_.assign(pixels_.size() * static_cast<std::size_t>(2 * options_.steps + 1), 0.0f);
  counts_.assign(pixels_.size(), 0);
  return pixels_.empty() ? std::vector<int>() : chosen;
}

namespace {

// What one neighbour's ZNCC of one block of up to 8 refined pixels needs.
struct BlockGeometry {
  int lanes = 0;
  bool inside[8] = {};                      // the view sees every sample of every hypothesis
  float centre_x[8], centre_y[8], centre_z[8];  // M p + ζ0 e
  // The homography's columns for the patch's x and y offsets: M's first two
  // columns plus the plane's inverse-depth slope times e (M_0 + ζ_x e, M_1 + ζ_y e).
  float m0x[8], m0y[8], m0z[8], m1x[8], m1y[8], m1z[8];
};

struct ViewGeometry {
  const float* grey = nullptr;
  std::size_t stride = 0;  // floats per row
  float e[3];
  float zeta_step = 0;
  int steps = 0, radius = 0, n = 0;
};

// ZNCC of every hypothesis of one pixel (lane) of the block, added to
// score[0 .. 2 steps]. Positions: the plane's homography, affine over the
// patch (one division per hypothesis; over a few pixels at <= 5° it is affine
// to well under 0.01 px). Written so that the AVX2 path below does the same
// float operations in the same order.
void ScoreLaneScalar(const ViewGeometry& g, const BlockGeometry& b, int lane, const float* ref_block,
                     float ref_norm, float* score) {
  const int r = g.radius;
  const float nf = static_cast<float>(g.n);
  for (int k = 0; k <= 2 * g.steps; ++k) {
    const float t = static_cast<float>(k - g.steps) * g.zeta_step;
    const float hx = b.centre_x[lane] + t * g.e[0], hy = b.centre_y[lane] + t * g.e[1], hz = b.centre_z[lane] + t * g.e[2];
    const float inv = 1.0f / hz;
    const float cx = hx * inv, cy = hy * inv;
    const float j0x = (b.m0x[lane] - cx * b.m0z[lane]) * inv, j0y = (b.m0y[lane] - cy * b.m0z[lane]) * inv;
    const float j1x = (b.m1x[lane] - cx * b.m1z[lane]) * inv, j1y = (b.m1y[lane] - cy * b.m1z[lane]) * inv;
    float sum = 0, sum_sq = 0, cross = 0;
    int s = 0;
    for (int bb = -r; bb <= r; ++bb)
      for (int a = -r; a <= r; ++a, ++s) {
        const float fa = static_cast<float>(a), fb = static_cast<float>(bb);
        const float x = cx + (fa * j0x + fb * j1x) - 0.5f, y = cy + (fa * j0y + fb * j1y) - 0.5f;
        const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
        const float ax = x - static_cast<float>(x0), ay = y - static_cast<float>(y0);
        const float* p = g.grey + static_cast<std::size_t>(y0) * g.stride + static_cast<std::size_t>(x0);
        const float v = (1 - ay) * ((1 - ax) * p[0] + ax * p[1]) + ay * ((1 - ax) * p[g.stride] + ax * p[g.stride + 1]);
        sum += v;
        sum_sq += v * v;
        cross += v * ref_block[s * 8 + lane];  // the reference patch is zero-mean: Σ(v − μ)·p = Σ v·p
      }
    const float var = sum_sq - sum * sum / nf;
    score[k] += var > 1e-12f ? cross / (std::sqrt(var) * ref_norm) : 0.0f;
  }
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define LFRECON_REFINE_AVX2 1
bool RefinementCpuHasAvx2() {
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
}

// ScoreLaneScalar for the 8 lanes at once (lanes not inside read a safe
// pixel and are not added).
__attribute__((target("avx2"))) void ScoreBlockAvx2(const ViewGeometry& g, const BlockGeometry& b,
                                                     const float* ref_block, const float* ref_norm,
                                                     float* const* score) {
  const int r = g.radius;
  const __m256 one = _mm256_set1_ps(1.0f), half = _mm256_set1_ps(0.5f), nf = _mm256_set1_ps(static_cast<float>(g.n));
  __m256 ok_mask;
  {
    alignas(32) float ok[8];
    for (int l = 0; l < 8; ++l) ok[l] = l < b.lanes && b.inside[l] ? 1.0f : 0.0f;
    ok_mask = _mm256_cmp_ps(_mm256_load_ps(ok), _mm256_setzero_ps(), _CMP_GT_OQ);
  }
  const __m256 bx = _mm256_loadu_ps(b.centre_x), by = _mm256_loadu_ps(b.centre_y), bz = _mm256_loadu_ps(b.centre_z);
  const __m256 norm = _mm256_loadu_ps(ref_norm);
  const __m256 m0x = _mm256_loadu_ps(b.m0x), m0y = _mm256_loadu_ps(b.m0y), m0z = _mm256_loadu_ps(b.m0z);
  const __m256 m1x = _mm256_loadu_ps(b.m1x), m1y = _mm256_loadu_ps(b.m1y), m1z = _mm256_loadu_ps(b.m1z);
  const __m256i stride = _mm256_set1_epi32(static_cast<int>(g.stride));
  const __m256 safe = _mm256_set1_ps(0.75f);  // a position inside any frame of 2x2 pixels or more
  for (int k = 0; k <= 2 * g.steps; ++k) {
    const __m256 t = _mm256_set1_ps(static_cast<float>(k - g.steps) * g.zeta_step);
    const __m256 hx = _mm256_add_ps(bx, _mm256_mul_ps(t, _mm256_set1_ps(g.e[0])));
    const __m256 hy = _mm256_add_ps(by, _mm256_mul_ps(t, _mm256_set1_ps(g.e[1])));
    const __m256 hz = _mm256_add_ps(bz, _mm256_mul_ps(t, _mm256_set1_ps(g.e[2])));
    const __m256 inv = _mm256_div_ps(one, hz);
    const __m256 cx = _mm256_mul_ps(hx, inv), cy = _mm256_mul_ps(hy, inv);
    const __m256 j0x = _mm256_mul_ps(_mm256_sub_ps(m0x, _mm256_mul_ps(cx, m0z)), inv);
    const __m256 j0y = _mm256_mul_ps(_mm256_sub_ps(m0y, _mm256_mul_ps(cy, m0z)), inv);
    const __m256 j1x = _mm256_mul_ps(_mm256_sub_ps(m1x, _mm256_mul_ps(cx, m1z)), inv);
    const __m256 j1y = _mm256_mul_ps(_mm256_sub_ps(m1y, _mm256_mul_ps(cy, m1z)), inv);
    __m256 sum = _mm256_setzero_ps(), sum_sq = _mm256_setzero_ps(), cross = _mm256_setzero_ps();
    int s = 0;
    for (int bb = -r; bb <= r; ++bb)
      for (int a = -r; a <= r; ++a, ++s) {
        const __m256 fa = _mm256_set1_ps(static_cast<float>(a)), fb = _mm256_set1_ps(static_cast<float>(bb));
        __m256 x = _mm256_sub_ps(_mm256_add_ps(cx, _mm256_add_ps(_mm256_mul_ps(fa, j0x), _mm256_mul_ps(fb, j1x))), half);
        __m256 y = _mm256_sub_ps(_mm256_add_ps(cy, _mm256_add_ps(_mm256_mul_ps(fa, j0y), _mm256_mul_ps(fb, j1y))), half);
        x = _mm256_blendv_ps(safe, x, ok_mask);
        y = _mm256_blendv_ps(safe, y, ok_mask);
        const __m256i x0 = _mm256_cvttps_epi32(x), y0 = _mm256_cvttps_epi32(y);
        const __m256 ax = _mm256_sub_ps(x, _mm256_cvtepi32_ps(x0)), ay = _mm256_sub_ps(y, _mm256_cvtepi32_ps(y0));
        const __m256i idx = _mm256_add_epi32(_mm256_mullo_epi32(y0, stride), x0);
        const __m256 p00 = _mm256_i32gather_ps(g.grey, idx, 4);
        const __m256 p01 = _mm256_i32gather_ps(g.grey + 1, idx, 4);
        const __m256 p10 = _mm256_i32gather_ps(g.grey + g.stride, idx, 4);
        const __m256 p11 = _mm256_i32gather_ps(g.grey + g.stride + 1, idx, 4);
        const __m256 wx = _mm256_sub_ps(one, ax), wy = _mm256_sub_ps(one, ay);
        const __m256 top = _mm256_add_ps(_mm256_mul_ps(wx, p00), _mm256_mul_ps(ax, p01));
        const __m256 bottom = _mm256_add_ps(_mm256_mul_ps(wx, p10), _mm256_mul_ps(ax, p11));
        const __m256 v = _mm256_add_ps(_mm256_mul_ps(wy, top), _mm256_mul_ps(ay, bottom));
        sum = _mm256_add_ps(sum, v);
        sum_sq = _mm256_add_ps(sum_sq, _mm256_mul_ps(v, v));
        cross = _mm256_add_ps(cross, _mm256_mul_ps(v, _mm256_loadu_ps(ref_block + s * 8)));
      }
    const __m256 var = _mm256_sub_ps(sum_sq, _mm256_div_ps(_mm256_mul_ps(sum, sum), nf));
    const __m256 zncc = _mm256_div_ps(cross, _mm256_mul_ps(_mm256_sqrt_ps(var), norm));
    const __m256 value = _mm256_and_ps(zncc, _mm256_cmp_ps(var, _mm256_set1_ps(1e-12f), _CMP_GT_OQ));
    alignas(32) float out[8];
    _mm256_store_ps(out, value);
    for (int l = 0; l < b.lanes; ++l)
      if (b.inside[l]) score[l][k] += out[l];
  }
}
#endif

}  // namespace

void PhotometricRefinementAccumulator::Add(const ViewImage& neighbor) {
  if (pixels_.empty() || !UsableImage(&neighbor)) return;
  const cv::Mat grey = PhotometricGrey(neighbor);
  CV_Assert(grey.isContinuous() || grey.step[0] % sizeof(float) == 0);
  // x_j ~ K_j (R_rel · d K_ref⁻¹ p + t_rel) ∝ M p + ζ e with ζ = 1/d: linear in
  // the pixel and in the inverse depth.
  const PinholeView& ref = reference_view_;
  const PinholeView& nb = neighbor.view;
  const Eigen::Matrix3d r_rel = nb.R * ref.R.transpose();
  const Eigen::Vector3d t_rel = nb.t - r_rel * ref.t;
  const Eigen::Matrix3f m = (nb.K * r_rel * ref.K_inv).cast<float>();
  const Eigen::Vector3f e = (nb.K * t_rel).cast<float>();
  ViewGeometry g;
  g.grey = grey.ptr<float>(0);
  g.stride = grey.step[0] / sizeof(float);
  for (int c = 0; c < 3; ++c) g.e[c] = e[c];
  g.zeta_step = static_cast<float>(zeta_step_);
  g.steps = options_.steps;
  g.radius = options_.patch_radius_px;
  g.n = (2 * g.radius + 1) * (2 * g.radius + 1);
  const int r = g.radius, hyps = 2 * options_.steps + 1;
  // Samples must fall where the bilinear 2x2 is inside: [0.5, size - 0.5).
  const float x_max = static_cast<float>(grey.cols) - 0.5f - 1e-3f, y_max = static_cast<float>(grey.rows) - 0.5f - 1e-3f;
  const Eigen::Vector3f m0 = m.col(0), m1 = m.col(1);
#ifdef LFRECON_REFINE_AVX2
  const bool avx2 = options_.simd && RefinementCpuHasAvx2();
#endif
  const std::size_t blocks = (pixels_.size() + 7) / 8;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks, 32), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t blk = range.begin(); blk != range.end(); ++blk) {
      BlockGeometry b;
      b.lanes = static_cast<int>(std::min<std::size_t>(8, pixels_.size() - blk * 8));
      bool any = false;
      for (int l = 0; l < 8; ++l) {
        b.centre_x[l] = b.centre_y[l] = 0;
        b.centre_z[l] = 1;
        b.m0x[l] = m0.x(), b.m0y[l] = m0.y(), b.m0z[l] = m0.z();
        b.m1x[l] = m1.x(), b.m1y[l] = m1.y(), b.m1z[l] = m1.z();
        if (l >= b.lanes) continue;
        const std::size_t i = blk * 8 + static_cast<std::size_t>(l);
        // The plane's columns (M_0 + ζ_x e, M_1 + ζ_y e); M's own when fronto-parallel.
        const Eigen::Vector3f pm0 = slope_x_[i] != 0 ? Eigen::Vector3f(m0 + slope_x_[i] * e) : m0;
        const Eigen::Vector3f pm1 = slope_y_[i] != 0 ? Eigen::Vector3f(m1 + slope_y_[i] * e) : m1;
        b.m0x[l] = pm0.x(), b.m0y[l] = pm0.y(), b.m0z[l] = pm0.z();
        b.m1x[l] = pm1.x(), b.m1y[l] = pm1.y(), b.m1z[l] = pm1.z();
        const int px = pixels_[i] % cols_, py = pixels_[i] / cols_;
        const Eigen::Vector3f centre =
            m * Eigen::Vector3f(static_cast<float>(px) + 0.5f, static_cast<float>(py) + 0.5f, 1.0f) + zeta0_[i] * e;
        b.centre_x[l] = centre.x();
        b.centre_y[l] = centre.y();
        b.centre_z[l] = centre.z();
        // Every sample of every hypothesis inside the frame and in front of it, or the view is skipped for this pixel.
        bool inside = true;
        for (int k = 0; k < hyps && inside; k += hyps - 1) {
          const Eigen::Vector3f h0 = centre + (static_cast<float>(k - options_.steps) * g.zeta_step) * e;
          for (int corner = 0; corner < 4 && inside; ++corner) {
            const float a = (corner & 1) ? static_cast<float>(r) + 1 : -static_cast<float>(r) - 1;
            const float bb = (corner & 2) ? static_cast<float>(r) + 1 : -static_cast<float>(r) - 1;
            const Eigen::Vector3f h = h0 + a * pm0 + bb * pm1;
            if (!(h.z() > 0) || !(h0.z() > 0)) {
              inside = false;
              break;
            }
            const float x = h.x() / h.z(), y = h.y() / h.z();
            if (!(x >= 0.5f && x < x_max && y >= 0.5f && y < y_max)) inside = false;
          }
        }
        b.inside[l] = inside;
        any = any || inside;
      }
      if (!any) continue;
      const float* ref_block = &ref_patch_[blk * 8 * static_cast<std::size_t>(g.n)];
#ifdef LFRECON_REFINE_AVX2
      if (avx2) {
        float* score[8];
        for (int l = 0; l < 8; ++l)
          score[l] = l < b.lanes ? &scores_[(blk * 8 + static_cast<std::size_t>(l)) * static_cast<std::size_t>(hyps)] : nullptr;
        ScoreBlockAvx2(g, b, ref_block, &ref_norm_[blk * 8], score);
      } else
#endif
      {
        for (int l = 0; l < b.lanes; ++l)
          if (b.inside[l])
            ScoreLaneScalar(g, b, l, ref_block, ref_norm_[blk * 8 + static_cast<std::size_t>(l)],
                            &scores_[(blk * 8 + static_cast<std::size_t>(l)) * static_cast<std::size_t>(hyps)]);
      }
      for (int l = 0; l < b.lanes; ++l)
        if (b.inside[l]) ++counts_[blk * 8 + static_cast<std::size_t>(l)];
    }
  });
}

int PhotometricRefinementAccumulator::Finish(DepthMap* dense) {
  const int hyps = 2 * options_.steps + 1;
  int changed = 0;
  for (std::size_t i = 0; i < pixels_.size(); ++i) {
    if (counts_[i] < options_.min_views) continue;
    const float* score = &scores_[i * static_cast<std::size_t>(hyps)];
    const int best = static_cast<int>(std::max_element(score, score + hyps) - score);
    if (best == 0 || best == hyps - 1) continue;  // the optimum lies beyond the range
    if (score[best] < options_.ncc_min * static_cast<float>(counts_[i])) continue;
    const float l = score[best - 1], c = score[best], rr = score[best + 1];
    const float curvature = l - 2 * c + rr;
    const float offset = curvature < 0 ? std::clamp(0.5f * (l - rr) / curvature, -0.5f, 0.5f) : 0.0f;
    const float zeta = zeta0_[i] + (static_cast<float>(best - options_.steps) + offset) * static_cast<float>(zeta_step_);
    if (!(zeta > 0)) continue;
    const int y = pixels_[i] / cols_, x = pixels_[i] % cols_;
    dense->depth.at<float>(y, x) = 1.0f / zeta;
    if (options_.raise_confidence && dense->confidence.size() == dense->depth.size()) {
      float& confidence = dense->confidence.at<float>(y, x);
      confidence = std::max(confidence, c / static_cast<float>(counts_[i]));
    }
    ++changed;
  }
  return changed;
}

int RefineDepthPhotometrically(const ViewImage& reference, const std::vector<const ViewImage*>& neighbors,
                               const PhotometricRefinementOptions& options, DepthMap* dense, const cv::Mat& keep) {
  if (options.views <= 0) return 0;
  const UsableNeighbors usable = FindUsableNeighbors(neighbors);
  PhotometricRefinementAccumulator acc(options);
  for (int j : acc.Begin(reference, *dense, usable.views, keep)) acc.Add(*usable.images[static_cast<std::size_t>(j)]);
  return acc.Finish(dense);
}

}  // namespace lfrecon
