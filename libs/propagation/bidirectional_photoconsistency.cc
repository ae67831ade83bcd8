#include "propagation/bidirectional_photoconsistency.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <cstring>
#include <opencv2/imgproc.hpp>
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#endif

#include "propagation/image_sampling.h"
#include "propagation/neighbor_views.h"
#include "util/error.h"

namespace lfrecon {

void PhotoconsistencyOptions::Check() const {
  LFRECON_CHECK_OPTION(sigma_p > 0);
  LFRECON_CHECK_OPTION(chroma_weight >= 0 && chroma_weight <= 1);
  LFRECON_CHECK_OPTION(samples_per_side >= 1 && samples_per_side <= 16);
  LFRECON_CHECK_OPTION(sample_step_px > 0 && sample_step_px <= 8);
  LFRECON_CHECK_OPTION(max_view_angle_deg > 0 && max_view_angle_deg < 90);
  LFRECON_CHECK_OPTION(silhouette_ratio >= 0 && silhouette_ratio < 1);
  LFRECON_CHECK_OPTION(presmooth_sigma >= 0 && presmooth_sigma <= 5);
  LFRECON_CHECK_OPTION(max_views >= 0);
}

cv::Mat EdgeConsistency::SilhouetteRatio() const {
  cv::Mat ratio = cv::Mat::zeros(c_plus.size(), CV_32F);
  for (int r = 0; r < ratio.rows; ++r) {
    const float* cp = c_plus.ptr<float>(r);
    const float* cm = c_minus.ptr<float>(r);
    float* out = ratio.ptr<float>(r);
    for (int c = 0; c < ratio.cols; ++c) {
      const float sum = cp[c] + cm[c];
      out[c] = sum > 0 ? std::abs(cp[c] - cm[c]) / sum : 0.0f;
    }
  }
  return ratio;
}

cv::Mat EdgeConsistency::Classify(double silhouette_ratio) const {
  cv::Mat classes = cv::Mat::zeros(c_plus.size(), CV_8U);
  for (int r = 0; r < classes.rows; ++r) {
    const float* cp = c_plus.ptr<float>(r);
    const float* cm = c_minus.ptr<float>(r);
    const std::uint8_t* ev = evaluated.ptr<std::uint8_t>(r);
    std::uint8_t* out = classes.ptr<std::uint8_t>(r);
    for (int c = 0; c < classes.cols; ++c) {
      if (!ev[c]) continue;
      const float sum = cp[c] + cm[c];
      EdgeClass k = EdgeClass::kUnresolved;
      if (sum > 0) k = std::abs(cp[c] - cm[c]) / sum > silhouette_ratio ? EdgeClass::kSilhouette : EdgeClass::kTexture;
      out[c] = static_cast<std::uint8_t>(k);
    }
  }
  return classes;
}

cv::Mat GradientDirection(const cv::Mat& image_bgr) {
  cv::Mat grey, gx, gy;
  cv::cvtColor(image_bgr, grey, cv::COLOR_BGR2GRAY);
  cv::Sobel(grey, gx, CV_32F, 1, 0, 3, 1.0 / 8.0);
  cv::Sobel(grey, gy, CV_32F, 0, 1, 3, 1.0 / 8.0);
  cv::Mat dir(image_bgr.size(), CV_32FC2);
  for (int r = 0; r < dir.rows; ++r) {
    const float* x = gx.ptr<float>(r);
    const float* y = gy.ptr<float>(r);
    cv::Vec2f* out = dir.ptr<cv::Vec2f>(r);
    for (int c = 0; c < dir.cols; ++c) {
      const float n = std::sqrt(x[c] * x[c] + y[c] * y[c]);
      // θ(p) = atan(∇_y I / ∇_x I) (eq. 8), kept as a unit vector so the sign
      // of the gradient fixes which side is "positive".
      out[c] = n > 1e-7f ? cv::Vec2f(x[c] / n, y[c] / n) : cv::Vec2f(0, 0);
    }
  }
  return dir;
}

namespace {

// The image the samples are taken from: `smoothed` when it is there (and
// presmooth_sigma > 0), else a copy smoothed into *local, or the frame itself.
const cv::Mat& SourceImage(const ViewImage& v, const PhotoconsistencyOptions& o, cv::Mat* local) {
  if (o.presmooth_sigma <= 0) return v.image;
  if (!v.smoothed.empty() && v.smoothed.size() == v.image.size() && v.smoothed.type() == CV_32FC3) return v.smoothed;
  cv::GaussianBlur(v.image, *local, cv::Size(0, 0), o.presmooth_sigma);
  return *local;
}

}  // namespace

BidirectionalPhotoconsistency::BidirectionalPhotoconsistency(const PhotoconsistencyOptions& options)
    : options_(options) {
  options_.Check();
}

std::vector<int> BidirectionalPhotoconsistency::SelectNeighbors(
    const PinholeView& reference, const std::vector<const PinholeView*>& neighbors) const {
  const PhotoconsistencyOptions& o = options_;
  // Usable neighbours within the angle, by increasing angle.
  std::vector<std::pair<double, int>> usable;
  for (std::size_t j = 0; j < neighbors.size(); ++j) {
    if (!neighbors[j]) continue;
    const double angle = UsableAngle(reference, *neighbors[j], o.max_view_angle_deg);
    if (angle < 0) continue;
    usable.emplace_back(angle, static_cast<int>(j));
  }
  std::stable_sort(usable.begin(), usable.end(), [](const auto& x, const auto& y) { return x.first < y.first; });
  std::vector<int> order;
  if (o.max_views > 0 && static_cast<int>(usable.size()) > o.max_views) {
    for (int k = 0; k < o.max_views; ++k)
      order.push_back(usable[static_cast<std::size_t>(k) * usable.size() / o.max_views].second);
  } else {
    for (const auto& u : usable) order.push_back(u.second);
  }
  return order;
}

EdgeConsistency BidirectionalPhotoconsistency::Compute(const ViewImage& reference,
                                                       const std::vector<const ViewImage*>& neighbors,
                                                       const DepthMap& depth) const {
  const UsableNeighbors usable = FindUsableNeighbors(neighbors);
  PhotoconsistencyAccumulator acc(options_);
  acc.Begin(reference, depth);
  for (int j : SelectNeighbors(reference.view, usable.views)) acc.Add(*usable.images[static_cast<std::size_t>(j)]);
  return acc.Finish();
}

PhotoconsistencyAccumulator::PhotoconsistencyAccumulator(const PhotoconsistencyOptions& options) : options_(options) {
  options_.Check();
}

void PhotoconsistencyAccumulator::Begin(const ViewImage& reference, const DepthMap& depth) {
  const PhotoconsistencyOptions& o = options_;
  const int rows = reference.image.rows, cols = reference.image.cols;
  out_ = EdgeConsistency();
  out_.c_plus = cv::Mat::zeros(rows, cols, CV_32F);
  out_.c_minus = cv::Mat::zeros(rows, cols, CV_32F);
  out_.direction = cv::Mat::zeros(rows, cols, CV_32FC2);
  out_.evaluated = cv::Mat::zeros(rows, cols, CV_8U);
  if (o.centre_consistency) out_.c_centre = cv::Mat::zeros(rows, cols, CV_32F);
  num_pixels_ = 0;
  added_ = 0;
  valid_ = false;
  reference_view_ = reference.view;
  if (reference.image.empty() || reference.image.type() != CV_32FC3 || depth.depth.empty() ||
      depth.depth.type() != CV_32F || depth.depth.size() != reference.image.size())
    return;
  valid_ = true;
  out_.direction = GradientDirection(reference.image);
  cv::Mat local;
  const cv::Mat& ref_img = SourceImage(reference, o, &local);

  // Pixels with a depth and a gradient direction, counted per row so that
  // the rows fill their own parts of the arrays in parallel.
  auto wanted = [&](int r, int c) {
    const float d = depth.depth.ptr<float>(r)[c];
    const cv::Vec2f n = out_.direction.ptr<cv::Vec2f>(r)[c];
    return d > 0 && std::isfinite(d) && (n[0] != 0 || n[1] != 0);
  };
  std::vector<std::size_t> first(static_cast<std::size_t>(rows) + 1, 0);
  tbb::parallel_for(0, rows, [&](int r) {
    std::size_t n = 0;
    for (int c = 0; c < cols; ++c) n += wanted(r, c);
    first[static_cast<std::size_t>(r) + 1] = n;
  });
  for (int r = 0; r < rows; ++r) first[r + 1] += first[r];
  num_pixels_ = first[rows];
  const std::size_t padded = (num_pixels_ + kLanes - 1) / kLanes * kLanes;
  const int S = o.samples_per_side;
  const std::size_t values = static_cast<std::size_t>(6 * S + (o.centre_consistency ? 9 : 0));
  row_.assign(padded, 0);
  col_.assign(padded, 0);
  for (std::vector<float>* v : {&d_, &px_, &py_, &sx_, &sy_, &sum_rho_[0], &sum_rho_[1], &count_[0], &count_[1],
                                &sum_centre_, &count_centre_})
    v->assign(padded, 0.0f);
  for (std::vector<std::int32_t>* v : {&side_ok_[0], &side_ok_[1], &centre_ok_}) v->assign(padded, 0);
  static ScratchPool sample_buffers;
  samples_lease_ = sample_buffers.Acquire(padded * values * sizeof(float));
  samples_ = static_cast<float*>(samples_lease_.data());
  std::fill(samples_, samples_ + padded * values, 0.0f);

  const float step_px = static_cast<float>(o.sample_step_px);
  tbb::parallel_for(0, rows, [&](int r) {
    std::vector<Eigen::Vector3f> f(2 * S + 3);  // f+ then f−, then C0's samples along the edge
    std::size_t i = first[r];
    for (int c = 0; c < cols; ++c) {
      if (!wanted(r, c)) continue;
      const cv::Vec2f n = out_.direction.ptr<cv::Vec2f>(r)[c];
      out_.evaluated.ptr<std::uint8_t>(r)[c] = 255;
      const Eigen::Vector2f p(c + 0.5f, r + 0.5f);
      const Eigen::Vector2f step = step_px * Eigen::Vector2f(n[0], n[1]);
      row_[i] = r;
      col_[i] = c;
      d_[i] = depth.depth.ptr<float>(r)[c];
      px_[i] = p.x();
      py_[i] = p.y();
      sx_[i] = step.x();
      sy_[i] = step.y();
      // Reference samples f+ (at p + k·step) and f− (at p − k·step).
      bool side_ok[2] = {true, true};
      for (int side = 0; side < 2; ++side) {
        const float sgn = side == 0 ? 1.0f : -1.0f;
        for (int k = 1; k <= S && side_ok[side]; ++k) {
          const Eigen::Vector2f x = p + (sgn * k) * step;
          side_ok[side] = SampleBgr(ref_img, x.x(), x.y(), &f[side * S + k - 1]);
        }
      }
      bool centre_ok = false;
      if ((side_ok[0] || side_ok[1]) && o.centre_consistency) {  // p − t, p, p + t with t ⊥ θ(p)
        const Eigen::Vector2f t(-step.y(), step.x());
        centre_ok = true;
        for (int k = -1; k <= 1 && centre_ok; ++k) {
          const Eigen::Vector2f x = p + static_cast<float>(k) * t;
          centre_ok = SampleBgr(ref_img, x.x(), x.y(), &f[2 * S + k + 1]);
        }
      }
      side_ok_[0][i] = side_ok[0] ? -1 : 0;
      side_ok_[1][i] = side_ok[1] ? -1 : 0;
      centre_ok_[i] = centre_ok ? -1 : 0;
      float* fs = samples_ + (i / kLanes) * values * kLanes + i % kLanes;
      for (int k = 0; k < 2 * S; ++k)
        if (side_ok[k / S])
          for (int ch = 0; ch < 3; ++ch) fs[(3 * k + ch) * kLanes] = f[k][ch];
      if (centre_ok)
        for (int k = 0; k < 3; ++k)
          for (int ch = 0; ch < 3; ++ch) fs[(6 * S + 3 * k + ch) * kLanes] = f[2 * S + k][ch];
      ++i;
    }
  });
}

// What Add needs of one neighbour: the plane homography's parts (y = d·A·x̃ + a,
// A = K_j R_ji K_i⁻¹, a = K_j t_ji; A row-major), the image and the constants of ρ.
struct PhotoconsistencyAccumulator::Neighbor {
  float A[9], a[3];
  const float* data = nullptr;  // CV_32FC3
  int stride = 0;               // floats per row
  float max_x = 0, max_y = 0;   // cols − 1, rows − 1: a sample is inside when x − ½ and y − ½ lie in [0, max)
  float chroma_weight = 1;
  float inv_two_sigma2 = 0, inv_two_sigma2_centre = 0;
  int samples_per_side = 3;
  std::size_t values = 0;       // floats per pixel in samples_
  bool centre = false;
};

namespace {

// Both paths below do the same float operations in the same order (no fused
// multiply-add: the AVX2 code is compiled without FMA, the scalar code for the
// x86-64 baseline), so they give the same bits.

// exp(x) for x <= 0 (Cephes' single-precision polynomial, relative error
// ~1e-7), the same operations as ExpNonPositive8 so that both paths agree to
// the bit; x below −87 (ρ < 2e-38) is taken as −87.
inline float ExpNonPositive(float x) {
  x = x > -87.0f ? x : -87.0f;
  const float n = std::floor(x * 1.44269504088896341f + 0.5f);
  x = x - n * 0.693359375f;
  x = x - n * -2.12194440e-4f;
  const float z = x * x;
  float y = 1.9875691500e-4f;
  y = y * x + 1.3981999507e-3f;
  y = y * x + 8.3334519073e-3f;
  y = y * x + 4.1665795894e-2f;
  y = y * x + 1.6666665459e-1f;
  y = y * x + 5.0000001201e-1f;
  y = y * z + x + 1.0f;
  const std::int32_t bits = (static_cast<std::int32_t>(n) + 127) << 23;
  float scale;
  std::memcpy(&scale, &bits, sizeof(scale));
  return y * scale;
}

// ‖f − g‖² with chroma weighted (ColourDifference2, written out in a fixed order).
inline float ColourDifference2Fixed(float d0, float d1, float d2, float chroma_weight) {
  if (chroma_weight == 1.0f) return d0 * d0 + d1 * d1 + d2 * d2;
  const float y = 0.114f * d0 + 0.587f * d1 + 0.299f * d2;
  const float e0 = d0 - y, e1 = d1 - y, e2 = d2 - y;
  return 3.0f * y * y + chroma_weight * (e0 * e0 + e1 * e1 + e2 * e2);
}

}  // namespace

void PhotoconsistencyAccumulator::AddPixel(std::size_t i, const Neighbor& nb) {
  const float* A = nb.A;
  const float d = d_[i], px = px_[i], py = py_[i], sx = sx_[i], sy = sy_[i];
  const float* fs = samples_ + (i / kLanes) * nb.values * kLanes + i % kLanes;
  // Through the plane at d: y(x) = d·A·x̃ + a is linear in x, so step along θ.
  const float y0[3] = {d * (A[0] * px + A[1] * py + A[2]) + nb.a[0], d * (A[3] * px + A[4] * py + A[5]) + nb.a[1],
                       d * (A[6] * px + A[7] * py + A[8]) + nb.a[2]};
  // Σ‖f − g‖² of the samples at y0 + t·dy, t = first, first + 1, ... (n of
  // them) against the reference's from value v0 on; false when one leaves the neighbour.
  auto ssd_along = [&](const float* dy, float first, int n, int v0, float* ssd) {
    *ssd = 0;
    for (int k = 0; k < n; ++k) {
      const float t = first + static_cast<float>(k);
      const float yx = y0[0] + t * dy[0], yy = y0[1] + t * dy[1], yz = y0[2] + t * dy[2];
      if (!(yz > 0)) return false;
      const float inv_z = 1.0f / yz;  // one division per sample (as the AVX2 path)
      const float fx = yx * inv_z - 0.5f, fy = yy * inv_z - 0.5f;
      if (!(fx >= 0.0f && fy >= 0.0f && fx < nb.max_x && fy < nb.max_y)) return false;
      const int x0 = static_cast<int>(fx), y0i = static_cast<int>(fy);
      const float ax = fx - static_cast<float>(x0), ay = fy - static_cast<float>(y0i);
      const float w00 = (1.0f - ax) * (1.0f - ay), w01 = ax * (1.0f - ay), w10 = (1.0f - ax) * ay, w11 = ax * ay;
      const float* r0 = nb.data + y0i * nb.stride + 3 * x0;
      const float* r1 = r0 + nb.stride;
      float g[3];
      for (int ch = 0; ch < 3; ++ch) g[ch] = w00 * r0[ch] + w01 * r0[3 + ch] + w10 * r1[ch] + w11 * r1[3 + ch];
      const float* f = fs + (v0 + 3 * k) * kLanes;
      *ssd += ColourDifference2Fixed(f[0] - g[0], f[kLanes] - g[1], f[2 * kLanes] - g[2], nb.chroma_weight);
    }
    return true;
  };
  const int S = nb.samples_per_side;
  const float dy[3] = {d * (A[0] * sx + A[1] * sy), d * (A[3] * sx + A[4] * sy), d * (A[6] * sx + A[7] * sy)};
  const float dy_minus[3] = {-dy[0], -dy[1], -dy[2]};
  for (int side = 0; side < 2; ++side) {
    if (!side_ok_[side][i]) continue;
    float ssd;  // samples at p ± k·step, k = 1..S
    if (!ssd_along(side == 0 ? dy : dy_minus, 1.0f, S, 3 * side * S, &ssd)) continue;
    sum_rho_[side][i] += ExpNonPositive(-ssd * nb.inv_two_sigma2);
    count_[side][i] += 1.0f;
  }
  if (nb.centre && centre_ok_[i]) {  // samples at p + k·t, k = −1, 0, 1, t ⊥ θ(p)
    const float dt[3] = {d * (A[0] * -sy + A[1] * sx), d * (A[3] * -sy + A[4] * sx), d * (A[6] * -sy + A[7] * sx)};
    float ssd;
    if (ssd_along(dt, -1.0f, 3, 6 * S, &ssd)) {
      sum_centre_[i] += ExpNonPositive(-ssd * nb.inv_two_sigma2_centre);
      count_centre_[i] += 1.0f;
    }
  }
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define LFRECON_PHOTO_AVX2 1
namespace {

bool CpuHasAvx2() {
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
}

#define LFRECON_AVX2 __attribute__((target("avx2")))

LFRECON_AVX2 inline __m256 ExpNonPositive8(__m256 x) {
  x = _mm256_max_ps(x, _mm256_set1_ps(-87.0f));
  const __m256 n = _mm256_floor_ps(
      _mm256_add_ps(_mm256_mul_ps(x, _mm256_set1_ps(1.44269504088896341f)), _mm256_set1_ps(0.5f)));
  x = _mm256_sub_ps(x, _mm256_mul_ps(n, _mm256_set1_ps(0.693359375f)));
  x = _mm256_sub_ps(x, _mm256_mul_ps(n, _mm256_set1_ps(-2.12194440e-4f)));
  const __m256 z = _mm256_mul_ps(x, x);
  __m256 y = _mm256_set1_ps(1.9875691500e-4f);
  y = _mm256_add_ps(_mm256_mul_ps(y, x), _mm256_set1_ps(1.3981999507e-3f));
  y = _mm256_add_ps(_mm256_mul_ps(y, x), _mm256_set1_ps(8.3334519073e-3f));
  y = _mm256_add_ps(_mm256_mul_ps(y, x), _mm256_set1_ps(4.1665795894e-2f));
  y = _mm256_add_ps(_mm256_mul_ps(y, x), _mm256_set1_ps(1.6666665459e-1f));
  y = _mm256_add_ps(_mm256_mul_ps(y, x), _mm256_set1_ps(5.0000001201e-1f));
  y = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(y, z), x), _mm256_set1_ps(1.0f));
  const __m256i bits = _mm256_slli_epi32(_mm256_add_epi32(_mm256_cvttps_epi32(n), _mm256_set1_epi32(127)), 23);
  return _mm256_mul_ps(y, _mm256_castsi256_ps(bits));
}

LFRECON_AVX2 inline __m256 ColourDifference2Fixed8(__m256 d0, __m256 d1, __m256 d2, float chroma_weight) {
  if (chroma_weight == 1.0f)
    return _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(d0, d0), _mm256_mul_ps(d1, d1)), _mm256_mul_ps(d2, d2));
  const __m256 y = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(_mm256_set1_ps(0.114f), d0),
                                               _mm256_mul_ps(_mm256_set1_ps(0.587f), d1)),
                                 _mm256_mul_ps(_mm256_set1_ps(0.299f), d2));
  const __m256 e0 = _mm256_sub_ps(d0, y), e1 = _mm256_sub_ps(d1, y), e2 = _mm256_sub_ps(d2, y);
  const __m256 e = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(e0, e0), _mm256_mul_ps(e1, e1)), _mm256_mul_ps(e2, e2));
  return _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(3.0f), y), y),
                       _mm256_mul_ps(_mm256_set1_ps(chroma_weight), e));
}

// a·x + b·y + c, in AddPixel's order.
LFRECON_AVX2 inline __m256 Dot3(float a, __m256 x, float b, __m256 y, float c) {
  return _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(_mm256_set1_ps(a), x), _mm256_mul_ps(_mm256_set1_ps(b), y)),
                       _mm256_set1_ps(c));
}
LFRECON_AVX2 inline __m256 Dot2(float a, __m256 x, float b, __m256 y) {
  return _mm256_add_ps(_mm256_mul_ps(_mm256_set1_ps(a), x), _mm256_mul_ps(_mm256_set1_ps(b), y));
}

// ssd_along of AddPixel for eight pixels at once: the lanes of `ok`, the
// reference's samples of this block from `fs`, projected points y0 + t·dy.
// Returns the lanes whose samples all lay inside the neighbour.
LFRECON_AVX2 inline __m256 SsdAlong8(const float* data, int stride_floats, float max_x_px, float max_y_px,
                                      float chroma_weight, const __m256* y0, const __m256* dy, float first, int n,
                                      const float* fs, __m256 ok, __m256* ssd) {
  constexpr int L = 8;
  const __m256 zero = _mm256_setzero_ps(), half = _mm256_set1_ps(0.5f), one = _mm256_set1_ps(1.0f);
  const __m256 max_x = _mm256_set1_ps(max_x_px), max_y = _mm256_set1_ps(max_y_px);
  const __m256i stride = _mm256_set1_epi32(stride_floats), three = _mm256_set1_epi32(3);
  *ssd = zero;
  for (int k = 0; k < n; ++k) {
    const __m256 t = _mm256_set1_ps(first + static_cast<float>(k));
    const __m256 yx = _mm256_add_ps(y0[0], _mm256_mul_ps(t, dy[0]));
    const __m256 yy = _mm256_add_ps(y0[1], _mm256_mul_ps(t, dy[1]));
    const __m256 yz = _mm256_add_ps(y0[2], _mm256_mul_ps(t, dy[2]));
    ok = _mm256_and_ps(ok, _mm256_cmp_ps(yz, zero, _CMP_GT_OQ));
    const __m256 inv_z = _mm256_div_ps(_mm256_set1_ps(1.0f), yz);
    __m256 fx = _mm256_sub_ps(_mm256_mul_ps(yx, inv_z), half), fy = _mm256_sub_ps(_mm256_mul_ps(yy, inv_z), half);
    ok = _mm256_and_ps(ok, _mm256_and_ps(_mm256_and_ps(_mm256_cmp_ps(fx, zero, _CMP_GE_OQ),
                                                       _mm256_cmp_ps(fy, zero, _CMP_GE_OQ)),
                                         _mm256_and_ps(_mm256_cmp_ps(fx, max_x, _CMP_LT_OQ),
                                                       _mm256_cmp_ps(fy, max_y, _CMP_LT_OQ))));
    if (_mm256_movemask_ps(ok) == 0) return ok;
    fx = _mm256_and_ps(fx, ok);  // lanes outside read pixel (0, 0) and are not counted
    fy = _mm256_and_ps(fy, ok);
    const __m256i x0 = _mm256_cvttps_epi32(fx), y0i = _mm256_cvttps_epi32(fy);
    const __m256 ax = _mm256_sub_ps(fx, _mm256_cvtepi32_ps(x0)), ay = _mm256_sub_ps(fy, _mm256_cvtepi32_ps(y0i));
    const __m256 bx = _mm256_sub_ps(one, ax), by = _mm256_sub_ps(one, ay);
    const __m256 w00 = _mm256_mul_ps(bx, by), w01 = _mm256_mul_ps(ax, by), w10 = _mm256_mul_ps(bx, ay),
                 w11 = _mm256_mul_ps(ax, ay);
    const __m256i i00 = _mm256_add_epi32(_mm256_mullo_epi32(y0i, stride), _mm256_mullo_epi32(x0, three));
    const __m256i i10 = _mm256_add_epi32(i00, stride);
    __m256 diff[3];
    for (int ch = 0; ch < 3; ++ch) {
      const __m256i c00 = _mm256_add_epi32(i00, _mm256_set1_epi32(ch));
      const __m256i c10 = _mm256_add_epi32(i10, _mm256_set1_epi32(ch));
      const __m256 r00 = _mm256_i32gather_ps(data, c00, 4);
      const __m256 r01 = _mm256_i32gather_ps(data, _mm256_add_epi32(c00, three), 4);
      const __m256 r10 = _mm256_i32gather_ps(data, c10, 4);
      const __m256 r11 = _mm256_i32gather_ps(data, _mm256_add_epi32(c10, three), 4);
      const __m256 g = _mm256_add_ps(
          _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(w00, r00), _mm256_mul_ps(w01, r01)), _mm256_mul_ps(w10, r10)),
          _mm256_mul_ps(w11, r11));
      diff[ch] = _mm256_sub_ps(_mm256_loadu_ps(fs + (3 * k + ch) * L), g);
    }
    *ssd = _mm256_add_ps(*ssd, ColourDifference2Fixed8(diff[0], diff[1], diff[2], chroma_weight));
  }
  return ok;
}

}  // namespace

LFRECON_AVX2 void PhotoconsistencyAccumulator::AddBlock(std::size_t block, const Neighbor& nb) {
  constexpr int L = kLanes;
  const std::size_t i = block * L;
  const float* A = nb.A;
  const __m256 d = _mm256_loadu_ps(&d_[i]), px = _mm256_loadu_ps(&px_[i]), py = _mm256_loadu_ps(&py_[i]);
  const __m256 sx = _mm256_loadu_ps(&sx_[i]), sy = _mm256_loadu_ps(&sy_[i]);
  const float* fs = samples_ + block * nb.values * L;
  const __m256 y0[3] = {_mm256_add_ps(_mm256_mul_ps(d, Dot3(A[0], px, A[1], py, A[2])), _mm256_set1_ps(nb.a[0])),
                        _mm256_add_ps(_mm256_mul_ps(d, Dot3(A[3], px, A[4], py, A[5])), _mm256_set1_ps(nb.a[1])),
                        _mm256_add_ps(_mm256_mul_ps(d, Dot3(A[6], px, A[7], py, A[8])), _mm256_set1_ps(nb.a[2]))};
  const __m256 one = _mm256_set1_ps(1.0f);
  const int S = nb.samples_per_side;
  const __m256 sign = _mm256_set1_ps(-0.0f);
  const __m256 dy[3] = {_mm256_mul_ps(d, Dot2(A[0], sx, A[1], sy)), _mm256_mul_ps(d, Dot2(A[3], sx, A[4], sy)),
                        _mm256_mul_ps(d, Dot2(A[6], sx, A[7], sy))};
  const __m256 dy_minus[3] = {_mm256_xor_ps(dy[0], sign), _mm256_xor_ps(dy[1], sign), _mm256_xor_ps(dy[2], sign)};
  for (int side = 0; side < 2; ++side) {
    const __m256 want = _mm256_castsi256_ps(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(&side_ok_[side][i])));
    if (_mm256_movemask_ps(want) == 0) continue;
    __m256 ssd;
    const __m256 ok = SsdAlong8(nb.data, nb.stride, nb.max_x, nb.max_y, nb.chroma_weight, y0, side == 0 ? dy : dy_minus,
                                 1.0f, S, fs + 3 * side * S * L, want, &ssd);
    const __m256 rho = ExpNonPositive8(_mm256_mul_ps(_mm256_xor_ps(ssd, sign), _mm256_set1_ps(nb.inv_two_sigma2)));
    _mm256_storeu_ps(&sum_rho_[side][i], _mm256_add_ps(_mm256_loadu_ps(&sum_rho_[side][i]), _mm256_and_ps(rho, ok)));
    _mm256_storeu_ps(&count_[side][i], _mm256_add_ps(_mm256_loadu_ps(&count_[side][i]), _mm256_and_ps(one, ok)));
  }
  if (!nb.centre) return;
  const __m256 want = _mm256_castsi256_ps(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(&centre_ok_[i])));
  if (_mm256_movemask_ps(want) == 0) return;
  const __m256 nsy = _mm256_xor_ps(sy, sign);
  const __m256 dt[3] = {_mm256_mul_ps(d, Dot2(A[0], nsy, A[1], sx)), _mm256_mul_ps(d, Dot2(A[3], nsy, A[4], sx)),
                        _mm256_mul_ps(d, Dot2(A[6], nsy, A[7], sx))};
  __m256 ssd;
  const __m256 ok =
      SsdAlong8(nb.data, nb.stride, nb.max_x, nb.max_y, nb.chroma_weight, y0, dt, -1.0f, 3, fs + 6 * S * L, want, &ssd);
  const __m256 rho = ExpNonPositive8(_mm256_mul_ps(_mm256_xor_ps(ssd, sign), _mm256_set1_ps(nb.inv_two_sigma2_centre)));
  _mm256_storeu_ps(&sum_centre_[i], _mm256_add_ps(_mm256_loadu_ps(&sum_centre_[i]), _mm256_and_ps(rho, ok)));
  _mm256_storeu_ps(&count_centre_[i], _mm256_add_ps(_mm256_loadu_ps(&count_centre_[i]), _mm256_and_ps(one, ok)));
}
#else
void PhotoconsistencyAccumulator::AddBlock(std::size_t block, const Neighbor& nb) {
  for (std::size_t i = block * kLanes; i < (block + 1) * kLanes; ++i) AddPixel(i, nb);
}
#endif

void PhotoconsistencyAccumulator::Add(const ViewImage& neighbor) {
  const PhotoconsistencyOptions& o = options_;
  if (!valid_ || !UsableImage(&neighbor)) return;
  if (UsableAngle(reference_view_, neighbor.view, o.max_view_angle_deg) < 0) return;
  ++added_;
  if (num_pixels_ == 0) return;
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  RelativePose(reference_view_, neighbor.view, &R, &t);
  const Eigen::Matrix3d A = neighbor.view.K * R * reference_view_.K_inv;
  const Eigen::Vector3d a = neighbor.view.K * t;
  cv::Mat local;
  const cv::Mat& image = SourceImage(neighbor, o, &local);
  Neighbor nb;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) nb.A[3 * r + c] = static_cast<float>(A(r, c));
    nb.a[r] = static_cast<float>(a(r));
  }
  nb.data = image.ptr<float>(0);
  nb.stride = static_cast<int>(image.step1());
  nb.max_x = static_cast<float>(image.cols - 1);
  nb.max_y = static_cast<float>(image.rows - 1);
  nb.chroma_weight = static_cast<float>(o.chroma_weight);
  nb.samples_per_side = o.samples_per_side;
  // exp(−‖f − g‖² / (2σ_p²)) (eq. 9), ‖·‖² per sample pixel (see header).
  nb.inv_two_sigma2 = static_cast<float>(1.0 / (2.0 * o.sigma_p * o.sigma_p * o.samples_per_side));
  nb.inv_two_sigma2_centre = static_cast<float>(1.0 / (2.0 * o.sigma_p * o.sigma_p * 3));
  nb.values = static_cast<std::size_t>(6 * o.samples_per_side + (o.centre_consistency ? 9 : 0));
  nb.centre = o.centre_consistency;
  bool simd = false;
#ifdef LFRECON_PHOTO_AVX2
  simd = o.simd && CpuHasAvx2();
#endif
  const std::size_t blocks = (num_pixels_ + kLanes - 1) / kLanes;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, blocks, 32), [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t b = range.begin(); b != range.end(); ++b)
      if (simd)
        AddBlock(b, nb);
      else
        for (std::size_t i = b * kLanes; i < (b + 1) * kLanes; ++i) AddPixel(i, nb);
  });
}

EdgeConsistency PhotoconsistencyAccumulator::Finish() {
  // Evaluated: every pixel with depth and a direction, once a neighbour took part.
  if (added_ == 0) {
    out_.evaluated.setTo(0);
  } else {
    for (std::size_t i = 0; i < num_pixels_; ++i) {
      // C+(p), C−(p): averages over the views (§4.1).
      out_.c_plus.at<float>(row_[i], col_[i]) = count_[0][i] > 0 ? sum_rho_[0][i] / count_[0][i] : 0.0f;
      out_.c_minus.at<float>(row_[i], col_[i]) = count_[1][i] > 0 ? sum_rho_[1][i] / count_[1][i] : 0.0f;
      if (!out_.c_centre.empty())
        out_.c_centre.at<float>(row_[i], col_[i]) = count_centre_[i] > 0 ? sum_centre_[i] / count_centre_[i] : 0.0f;
    }
  }
  EdgeConsistency result = std::move(out_);
  out_ = EdgeConsistency();
  for (std::vector<float>* v : {&d_, &px_, &py_, &sx_, &sy_, &sum_rho_[0], &sum_rho_[1], &count_[0], &count_[1],
                                &sum_centre_, &count_centre_})
    std::vector<float>().swap(*v);
  samples_lease_ = ScratchPool::Lease();
  samples_ = nullptr;
  for (std::vector<std::int32_t>* v : {&side_ok_[0], &side_ok_[1], &centre_ok_}) std::vector<std::int32_t>().swap(*v);
  std::vector<int>().swap(row_);
  std::vector<int>().swap(col_);
  num_pixels_ = 0;
  valid_ = false;
  added_ = 0;
  return result;
}

}  // namespace lfrecon
