#include "depth/gradient_depth_estimator.h"

#include <spdlog/spdlog.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/LU>
#include <algorithm>
#include <atomic>
#include <cmath>
#include <deque>
#include <opencv2/imgproc.hpp>
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#endif

#include "depth/image_sampling.h"
#include "geometry/view_graph.h"
#include "util/error.h"

namespace lfrecon {

void GradientDepthOptions::Check() const {
  LFRECON_CHECK_OPTION(gradient_threshold >= 0);
  LFRECON_CHECK_OPTION(patch_length >= 3 && patch_length <= 9 && patch_length % 2 == 1);
  LFRECON_CHECK_OPTION(patch_rows >= 1 && patch_rows <= 5 && patch_rows % 2 == 1);
  LFRECON_CHECK_OPTION(sigma_c > 0);
  LFRECON_CHECK_OPTION(max_view_angle_deg > 0 && max_view_angle_deg < 90);
  LFRECON_CHECK_OPTION(refine_reference_points >= 1);
  LFRECON_CHECK_OPTION(shift_iterations >= 0);
  LFRECON_CHECK_OPTION(shift_tolerance_px >= 0);
  LFRECON_CHECK_OPTION(outlier_pixels > 0);
  LFRECON_CHECK_OPTION(min_depth >= 0);
  LFRECON_CHECK_OPTION(max_depth <= 0 || max_depth > min_depth);
  LFRECON_CHECK_OPTION(max_reference_points >= 2);
  LFRECON_CHECK_OPTION(presmooth_sigma >= 0 && presmooth_sigma <= 5);
  LFRECON_CHECK_OPTION(std::isfinite(ray_margin));
  LFRECON_CHECK_OPTION(gradient_peak_fraction >= 0 && gradient_peak_fraction <= 1);
  LFRECON_CHECK_OPTION(level_angle_ratio >= 1.0);
  LFRECON_CHECK_OPTION(level_min_step_deg >= 0 && level_min_step_deg < max_view_angle_deg);
}

std::vector<char> HierarchyGrid(const std::vector<PinholeView>& views, const GradientDepthOptions& o) {
  if (!o.use_hierarchy) return std::vector<char>(views.size(), 1);
  return SpacedAtLeast(ViewingDirections(views), o.level_min_step_deg);
}

std::vector<int> SelectHierarchyViews(const PinholeView& vi, const std::vector<const PinholeView*>& neighbors,
                                      const std::vector<char>& on_grid, const GradientDepthOptions& o) {
  struct Cand {
    int index;
    double angle;
    Eigen::Vector3d baseline, dir;
  };
  const Eigen::Vector3d dir_i = vi.ViewingDirection();
  std::vector<Cand> pairs;
  for (size_t q = 0; q < neighbors.size(); ++q) {
    if (!neighbors[q]) continue;
    const Eigen::Vector3d dir = neighbors[q]->ViewingDirection();
    const double angle = AngleBetweenDeg(dir_i, dir);
    if (angle > o.max_view_angle_deg) continue;
    const Eigen::Vector3d baseline = neighbors[q]->Center() - vi.Center();
    if (baseline.norm() < 1e-9) continue;  // coincident camera: no parallax
    pairs.push_back({static_cast<int>(q), angle, baseline, dir});
  }
  std::sort(pairs.begin(), pairs.end(), [](const Cand& x, const Cand& y) {
    return x.angle < y.angle || (x.angle == y.angle && x.index < y.index);
  });
  std::vector<int> order;
  if (pairs.empty()) return order;
  // First level: the nearest view, and the nearest one on the other side of it.
  const Eigen::Vector3d b0 = pairs[0].baseline;
  auto side_of = [&](const Cand& c) { return c.baseline.dot(b0) < 0 ? 1 : 0; };
  std::vector<size_t> first_level = {0};
  for (size_t k = 1; k < pairs.size(); ++k)
    if (side_of(pairs[k])) {
      first_level.push_back(k);
      break;
    }
  for (size_t f : first_level) order.push_back(pairs[f].index);
  if (!o.use_hierarchy) return order;
  // Later levels, nearest first. On each side a view is used when it is on
  // the grid, its angle is at least level_angle_ratio times the last used
  // one's and it lies at least level_min_step_deg from it (the farthest grid
  // view always is): far views carry nearly all the depth information, and
  // one step keeps the prediction within the ±1 px search.
  const bool thin = o.level_min_step_deg > 0;
  auto grid = [&](const Cand& c) { return !thin || on_grid.empty() || on_grid[c.index]; };
  double last_angle[2] = {0, 0};
  Eigen::Vector3d last_dir[2] = {dir_i, dir_i};
  for (size_t f : first_level) {
    last_angle[side_of(pairs[f])] = pairs[f].angle;
    last_dir[side_of(pairs[f])] = pairs[f].dir;
  }
  int farthest[2] = {-1, -1};
  for (size_t k = 0; k < pairs.size(); ++k)
    if (grid(pairs[k]) && std::find(first_level.begin(), first_level.end(), k) == first_level.end())
      farthest[side_of(pairs[k])] = static_cast<int>(k);
  for (size_t k = 0; k < pairs.size(); ++k) {
    if (std::find(first_level.begin(), first_level.end(), k) != first_level.end() || !grid(pairs[k])) continue;
    const int side = side_of(pairs[k]);
    const bool far_enough = pairs[k].angle >= o.level_angle_ratio * last_angle[side] &&
                            (!thin || AtLeastStepDeg(AngleBetweenDeg(pairs[k].dir, last_dir[side]), o.level_min_step_deg));
    if (far_enough || static_cast<int>(k) == farthest[side]) {
      order.push_back(pairs[k].index);
      last_angle[side] = pairs[k].angle;
      last_dir[side] = pairs[k].dir;
    }
  }
  return order;
}

void PrepareViewImage(ViewImage* view, const GradientDepthOptions& options) {
  if (options.presmooth_sigma > 0)
    cv::GaussianBlur(view->image, view->smoothed, cv::Size(0, 0), options.presmooth_sigma);
  else
    view->smoothed = view->image;
  cv::cvtColor(view->smoothed, view->grey, cv::COLOR_BGR2GRAY);
}

namespace {
// Grey-level derivatives and ‖∇I‖ as the estimator thresholds them.
void GreyGradient(const cv::Mat& image_bgr, cv::Mat* gx, cv::Mat* gy, cv::Mat* mag) {
  cv::Mat grey;
  cv::cvtColor(image_bgr, grey, cv::COLOR_BGR2GRAY);
  // 3x3 Sobel / 8 = smoothed central difference per pixel.
  cv::Sobel(grey, *gx, CV_32F, 1, 0, 3, 1.0 / 8.0);
  cv::Sobel(grey, *gy, CV_32F, 0, 1, 3, 1.0 / 8.0);
  cv::magnitude(*gx, *gy, *mag);
}
}  // namespace

cv::Mat GradientMagnitude(const cv::Mat& image_bgr) {
  cv::Mat gx, gy, mag;
  GreyGradient(image_bgr, &gx, &gy, &mag);
  return mag;
}

cv::Mat GradientPeaks(const cv::Mat& image_bgr, double fraction) {
  cv::Mat gx, gy, mag;
  GreyGradient(image_bgr, &gx, &gy, &mag);
  cv::Mat out = cv::Mat::zeros(mag.size(), CV_32F);
  const int rows = mag.rows, cols = mag.cols;
  const float tan22 = 0.41421356f;  // tan 22.5°
  const float f = static_cast<float>(fraction);
  auto at = [&](int r, int c) { return r < 0 || c < 0 || r >= rows || c >= cols ? 0.0f : mag.ptr<float>(r)[c]; };
  tbb::parallel_for(0, rows, [&](int r) {
    const float* x = gx.ptr<float>(r);
    const float* y = gy.ptr<float>(r);
    const float* m = mag.ptr<float>(r);
    float* o = out.ptr<float>(r);
    for (int c = 0; c < cols; ++c) {
      const float ax = std::abs(x[c]), ay = std::abs(y[c]);
      int dr = 0, dc = 0;  // the neighbour along the gradient
      if (ay <= tan22 * ax) {
        dc = 1;
      } else if (ax <= tan22 * ay) {
        dr = 1;
      } else {
        dr = 1;
        dc = (x[c] > 0) == (y[c] > 0) ? 1 : -1;
      }
      if (m[c] >= f * std::max(at(r + dr, c + dc), at(r - dr, c - dc))) o[c] = m[c];
    }
  });
  return out;
}

namespace {

// AVX2 bilinear sampling of four grey samples at once (the patches' rows).
// Each lane does exactly the scalar FloatImage::Sample1 arithmetic (double
// coordinates, truncation, float weights, the same operations in the same
// order, no fused multiply-add), so results are bit-identical to it; the
// caller picks this path at run time only on CPUs with AVX2.
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#define LFRECON_DEPTH_AVX2 1
#define LFRECON_AVX2_FN __attribute__((target("avx2"))) inline
bool CpuHasAvx2() {
  static const bool has = __builtin_cpu_supports("avx2");
  return has;
}

// Bilinear samples at (x, y) of the lanes in `want` (all-ones lanes); the
// other lanes are not read. Returns the lanes that lie inside the image
// (FloatImage::Cell's test), a subset of `want`.
LFRECON_AVX2_FN __m256d Bilinear4(const FloatImage& img, __m256d x, __m256d y, __m256d want, __m128* out) {
  const __m256d half = _mm256_set1_pd(0.5), zero = _mm256_setzero_pd();
  const __m256d fx = _mm256_sub_pd(x, half), fy = _mm256_sub_pd(y, half);
  __m256d ok = _mm256_and_pd(_mm256_cmp_pd(fx, zero, _CMP_GE_OQ), _mm256_cmp_pd(fx, _mm256_set1_pd(img.max_x), _CMP_LT_OQ));
  ok = _mm256_and_pd(ok, _mm256_and_pd(_mm256_cmp_pd(fy, zero, _CMP_GE_OQ),
                                       _mm256_cmp_pd(fy, _mm256_set1_pd(img.max_y), _CMP_LT_OQ)));
  ok = _mm256_and_pd(ok, want);
  // Lanes outside get index 0 (never read: masked gathers).
  const __m256d fxs = _mm256_and_pd(fx, ok), fys = _mm256_and_pd(fy, ok);
  const __m128i x0 = _mm256_cvttpd_epi32(fxs), y0 = _mm256_cvttpd_epi32(fys);
  const __m128 ax = _mm256_cvtpd_ps(_mm256_sub_pd(fxs, _mm256_cvtepi32_pd(x0)));
  const __m128 ay = _mm256_cvtpd_ps(_mm256_sub_pd(fys, _mm256_cvtepi32_pd(y0)));
  const __m128i stride = _mm_set1_epi32(static_cast<int>(img.stride)), one = _mm_set1_epi32(1);
  const __m128i i00 = _mm_add_epi32(_mm_mullo_epi32(y0, stride), x0);
  const __m128i i10 = _mm_add_epi32(i00, stride);
  // The 64-bit lane mask packed to 32-bit lanes.
  const __m128 mask = _mm256_cvtpd_ps(_mm256_and_pd(ok, _mm256_set1_pd(-1.0)));
  const __m128 none = _mm_setzero_ps();
  const __m128 r00 = _mm_mask_i32gather_ps(none, img.data, i00, mask, 4);
  const __m128 r01 = _mm_mask_i32gather_ps(none, img.data, _mm_add_epi32(i00, one), mask, 4);
  const __m128 r10 = _mm_mask_i32gather_ps(none, img.data, i10, mask, 4);
  const __m128 r11 = _mm_mask_i32gather_ps(none, img.data, _mm_add_epi32(i10, one), mask, 4);
  const __m128 top = _mm_add_ps(r00, _mm_mul_ps(ax, _mm_sub_ps(r01, r00)));
  const __m128 bottom = _mm_add_ps(r10, _mm_mul_ps(ax, _mm_sub_ps(r11, r10)));
  *out = _mm_add_ps(top, _mm_mul_ps(ay, _mm_sub_ps(bottom, top)));
  return ok;
}

LFRECON_AVX2_FN __m256d Lanes(int k) { return _mm256_set_pd(k + 3, k + 2, k + 1, k); }

// Samples k..k+3 of a segment y0 + k·u; false if any lies outside.
LFRECON_AVX2_FN bool SampleSegment4(const FloatImage& img, const Eigen::Vector2d& y0, const Eigen::Vector2d& u, int k,
                                    float* out) {
  const __m256d kk = Lanes(k);
  const __m256d x = _mm256_add_pd(_mm256_set1_pd(y0.x()), _mm256_mul_pd(kk, _mm256_set1_pd(u.x())));
  const __m256d y = _mm256_add_pd(_mm256_set1_pd(y0.y()), _mm256_mul_pd(kk, _mm256_set1_pd(u.y())));
  __m128 v;
  const __m256d all = _mm256_castsi256_pd(_mm256_set1_epi64x(-1));
  if (_mm256_movemask_pd(Bilinear4(img, x, y, all, &v)) != 0xF) return false;
  _mm_storeu_ps(out, v);
  return true;
}

// The same samples with NaN where outside (SampleLine).
LFRECON_AVX2_FN void SampleSegmentOrNan4(const FloatImage& img, const Eigen::Vector2d& y0, const Eigen::Vector2d& u,
                                         int k, float* out) {
  const __m256d kk = Lanes(k);
  const __m256d x = _mm256_add_pd(_mm256_set1_pd(y0.x()), _mm256_mul_pd(kk, _mm256_set1_pd(u.x())));
  const __m256d y = _mm256_add_pd(_mm256_set1_pd(y0.y()), _mm256_mul_pd(kk, _mm256_set1_pd(u.y())));
  __m128 v;
  const __m256d all = _mm256_castsi256_pd(_mm256_set1_epi64x(-1));
  const __m256d ok = Bilinear4(img, x, y, all, &v);
  const __m128 ok32 = _mm256_cvtpd_ps(_mm256_and_pd(ok, _mm256_set1_pd(-1.0)));
  _mm_storeu_ps(out, _mm_blendv_ps(_mm_set1_ps(std::numeric_limits<float>::quiet_NaN()), v, ok32));
}

// Samples k..k+3 of the homogeneous segment base + k·step (dehomogenised);
// false if any has z <= 0 or lies outside.
LFRECON_AVX2_FN bool SampleProjective4(const FloatImage& img, const Eigen::Vector3d& base, const Eigen::Vector3d& step,
                                       int k, float* out) {
  const __m256d kk = Lanes(k);
  const __m256d hx = _mm256_add_pd(_mm256_set1_pd(base.x()), _mm256_mul_pd(kk, _mm256_set1_pd(step.x())));
  const __m256d hy = _mm256_add_pd(_mm256_set1_pd(base.y()), _mm256_mul_pd(kk, _mm256_set1_pd(step.y())));
  const __m256d hz = _mm256_add_pd(_mm256_set1_pd(base.z()), _mm256_mul_pd(kk, _mm256_set1_pd(step.z())));
  const __m256d front = _mm256_cmp_pd(hz, _mm256_setzero_pd(), _CMP_GT_OQ);
  if (_mm256_movemask_pd(front) != 0xF) return false;
  const __m256d inv_z = _mm256_div_pd(_mm256_set1_pd(1.0), hz);
  __m128 v;
  if (_mm256_movemask_pd(Bilinear4(img, _mm256_mul_pd(hx, inv_z), _mm256_mul_pd(hy, inv_z), front, &v)) != 0xF)
    return false;
  _mm_storeu_ps(out, v);
  return true;
}
#endif  // AVX2

// Geometry of one (reference i, neighbour j) pair that does not depend on the pixel.
struct PairGeometry {
  const ViewImage* view = nullptr;
  const cv::Mat* image = nullptr;  // the neighbour's smoothed colour image (for C^c)
  const cv::Mat* grey = nullptr;   // and its smoothed grey image (for the patches)
  FloatImage image_px, grey_px;    // the same two, for sampling
  Eigen::Matrix3d A;      // K_j R_ji K_i^-1: homogeneous j-pixel of p at depth d is d·A·p̃ + a
  Eigen::Vector3d a;      // K_j t_ji
  Eigen::Matrix3d A_inv;  // for H(d)^-1 by Sherman-Morrison
  Eigen::Vector3d g;      // A^-1 a
  Eigen::RowVector3d r3;  // third row of A^-1
  double r3a = 0;         // r3 · a
  Eigen::Vector3d baseline;  // C_j - C_i (world)
  double angle_deg = 0;
};

// The epipolar line of one pixel in one neighbour, parameterised by the
// coordinate S along its unit direction u (S grows with depth).
struct EpipolarRay {
  const PairGeometry* pair = nullptr;
  Eigen::Vector3d b;     // A p̃
  Eigen::Vector2d u, n;  // direction and normal of ℓ
  double w = 0;          // n · (any point of ℓ)

  bool Init(const PairGeometry& pg, const Eigen::Vector3d& p_h) {
    pair = &pg;
    b = pg.A * p_h;
    const Eigen::Vector2d num = b.head<2>() * pg.a.z() - pg.a.head<2>() * b.z();
    const double len = num.norm();
    if (!(len > 1e-12)) return false;  // no baseline along this ray: coincident cameras
    u = num / len;
    n = Eigen::Vector2d(-u.y(), u.x());
    w = n.dot(Pixel(1.0));
    return true;
  }
  Eigen::Vector2d Pixel(double d) const {
    const double z = d * b.z() + pair->a.z();
    return (d * b.head<2>() + pair->a.head<2>()) / z;
  }
  bool InFront(double d) const { return d * b.z() + pair->a.z() > 0; }
  double S(double d) const { return u.dot(Pixel(d)); }
  // Depth whose projection has line coordinate s; <= 0 if none in front.
  double Depth(double s) const {
    const double den = u.dot(b.head<2>()) - s * b.z();
    if (std::abs(den) < 1e-15) return -1;
    return (s * pair->a.z() - u.dot(pair->a.head<2>())) / den;
  }
  double dSdd(double d) const {
    const double z = d * b.z() + pair->a.z();
    return u.dot(b.head<2>() * pair->a.z() - pair->a.head<2>() * b.z()) / (z * z);
  }
  Eigen::Vector2d Point(double s) const { return s * u + w * n; }
  // Homogeneous j-pixel (or direction, z = 0) back to i through the plane
  // fronto-parallel to i at depth d: H(d)^-1 by Sherman-Morrison, since
  // H(d) = A + a e_z^T / d is a rank-one update of A.
  Eigen::Vector3d BackToReferenceH(const Eigen::Vector3d& yh, double d) const {
    return pair->A_inv * yh - pair->g * (pair->r3.dot(yh) / (d + pair->r3a));
  }
};

// Result of measuring the shift at one reference point.
struct ShiftMeasurement {
  bool valid = false;
  double shift = 0;     // δ: match is at S + δ (pixels along ℓ)
  double energy = 0;    // Σ gx², gradient energy along ℓ
  double log_colour = 0;  // log C^c at the match (eq. 4)
  // log C = log(C^c·C^d) (eq. 4, 5): scores are compared in the log domain, so
  // one exponential is taken per chosen candidate, not per measurement.
  double LogScore() const { return log_colour - shift * shift; }
};

class PixelSolver {
 public:
  PixelSolver(const GradientDepthOptions& o, const FloatImage& ref_grey, const Eigen::Vector3f& ref_colour)
      : o_(o), ref_grey_(ref_grey), ref_colour_(ref_colour), half_(o.patch_length / 2),
        inv_two_sigma_c2_(1.0 / (2.0 * o.sigma_c * o.sigma_c)) {
#ifdef LFRECON_DEPTH_AVX2
    avx2_ = CpuHasAvx2();
#endif
  }

  // Grey levels of I_j on ℓ at s0 - half, s0 - half + 1, ... (count + patch_length - 1
  // of them; NaN where the bilinear sample is outside): the patch rows on ℓ of
  // reference points s0, s0 + 1, ... overlap in all but one sample, so a scan
  // samples each point once.
  void SampleLine(const EpipolarRay& ray, double s0, int count, std::vector<float>* line) const {
    const int n = count + 2 * half_;
    line->resize(n);
    const Eigen::Vector2d y0 = ray.Point(s0 - half_);
    int t = 0;
#ifdef LFRECON_DEPTH_AVX2
    if (avx2_)
      for (; t + 4 <= n; t += 4) SampleSegmentOrNan4(ray.pair->grey_px, y0, ray.u, t, line->data() + t);
#endif
    for (; t < n; ++t) {
      const Eigen::Vector2d y = y0 + t * ray.u;
      float v;
      (*line)[t] = ray.pair->grey_px.Sample1(y.x(), y.y(), &v) ? v : std::numeric_limits<float>::quiet_NaN();
    }
  }

  // The reference side of the patch at line coordinate s (reference depth d =
  // D(s)): the points of I_i that the plane fronto-parallel to i at depth d
  // maps onto the `rows` rows of I_j's patch, sampled into si[rows][L]. False
  // if any lies behind i or outside I_i.
  bool ReferencePatch(const EpipolarRay& ray, double s, double d, int rows, float* si) const {
    const int L = 2 * half_ + 1;
    // The plane homography maps each segment on (or beside) ℓ to a segment in
    // I_i: map its start and direction once, then step (homogeneous coordinates).
    const Eigen::Vector3d step = ray.BackToReferenceH(Eigen::Vector3d(ray.u.x(), ray.u.y(), 0.0), d);
    const int half_rows = rows / 2;
    for (int row = -half_rows; row <= half_rows; ++row, si += L) {
      const Eigen::Vector2d y0 = ray.Point(s - half_) + row * ray.n;
      const Eigen::Vector3d base = ray.BackToReferenceH(Eigen::Vector3d(y0.x(), y0.y(), 1.0), d);
      int k = 0;
#ifdef LFRECON_DEPTH_AVX2
      if (avx2_)
        for (; k + 4 <= L; k += 4)
          if (!SampleProjective4(ref_grey_, base, step, k, si + k)) return false;
#endif
      for (; k < L; ++k) {
        const Eigen::Vector3d xh = base + k * step;
        if (!(xh.z() > 0)) return false;
        const double inv_z = 1.0 / xh.z();
        if (!ref_grey_.Sample1(xh.x() * inv_z, xh.y() * inv_z, &si[k])) return false;
      }
    }
    return true;
  }
  // ReferencePatch at line coordinate s into buf; buf, or null where there is
  // none (D(s) behind a camera, or a sample outside I_i).
  const float* ReferencePatchAt(const EpipolarRay& ray, double s, int rows, float* buf) const {
    const double d = ray.Depth(s);
    return d > 0 && ray.InFront(d) && ReferencePatch(ray, s, d, rows, buf) ? buf : nullptr;
  }

  // The 2×5 patch at line coordinate s (reference depth D(s)) and its least-squares shift.
  // line: when given (rows = 1 only), I_j's samples on ℓ from SampleLine starting at s.
  // with_colour: false leaves m.log_colour unset (the match's position is still
  // checked, so validity does not depend on it); Search samples it once at the final match.
  // ref_rows: when given, the reference side (ReferencePatch's si, `rows` rows)
  // to use instead of sampling it at D(s).
  ShiftMeasurement Measure(const EpipolarRay& ray, double s, int rows, const float* line = nullptr,
                           bool with_colour = true, const float* ref_rows = nullptr) const {
    ShiftMeasurement m;
    const double d = ray.Depth(s);
    if (!(d > 0) || !ray.InFront(d)) return m;
    const FloatImage& img_j = ray.pair->image_px;
    const FloatImage& grey_j = ray.pair->grey_px;
    const int L = 2 * half_ + 1;
    float si_rows[5 * 9];
    if (!ref_rows) {
      if (!ReferencePatch(ray, s, d, rows, si_rows)) return m;
      ref_rows = si_rows;
    }
    double sxy = 0, sxx = 0;
    float sj[9];
    const int half_rows = rows / 2;
    for (int row = -half_rows; row <= half_rows; ++row) {
      const float* si = ref_rows + (row + half_rows) * L;
      const Eigen::Vector2d y0 = ray.Point(s - half_) + row * ray.n;
      int k = 0;
      if (line) {
        for (; k < L; ++k) {
          sj[k] = line[k];
          if (std::isnan(sj[k])) return m;
        }
      }
#ifdef LFRECON_DEPTH_AVX2
      if (avx2_)
        for (; k + 4 <= L; k += 4)
          if (!SampleSegment4(grey_j, y0, ray.u, k, sj + k)) return m;
#endif
      for (; k < L; ++k) {
        const Eigen::Vector2d y = y0 + k * ray.u;
        if (!grey_j.Sample1(y.x(), y.y(), &sj[k])) return m;
      }
      // Least-squares shift over the interior columns: eq. 2-3 in robust form,
      // gx the patch gradient along ℓ, gy the difference between its rows.
      // Grey levels: colour gave the same accuracy at three times the cost.
      for (int k = 1; k + 1 < L; ++k) {
        const float gx = 0.25f * (si[k + 1] - si[k - 1] + sj[k + 1] - sj[k - 1]);
        const float gy = sj[k] - si[k];
        sxy += gx * gy;
        sxx += gx * gx;
      }
    }
    if (!(sxx > 1e-12)) return m;
    const double shift = -sxy / sxx;
    m.shift = shift;
    m.energy = sxx;
    m.valid = std::isfinite(m.shift);
    if (!m.valid) return m;
    const Eigen::Vector2d y = ray.Point(s + m.shift);
    if (!with_colour) {
      m.valid = img_j.Inside(y.x(), y.y());
      return m;
    }
    Eigen::Vector3f c;
    if (!img_j.Sample3(y.x(), y.y(), &c)) {
      m.valid = false;
      return m;
    }
    m.log_colour = -(c - ref_colour_).squaredNorm() * inv_two_sigma_c2_;
    return m;
  }

  // Best of the reference points s0, s0+1, ... (count of them) by C = C^c·C^d,
  // then Gauss-Newton on the shift. Returns the match coordinate, or NaN.
  double Search(const EpipolarRay& ray, double s0, int count, ShiftMeasurement* best_out,
                std::vector<float>* line) const {
    double best_c = -std::numeric_limits<double>::infinity(), best_s = std::numeric_limits<double>::quiet_NaN();
    ShiftMeasurement best;
    // The reference side of every patch of this search, sampled once at the
    // middle reference point's depth (reuse_reference_patch).
    const int L = 2 * half_ + 1;
    float ref[5 * 9];
    const float* ref_rows =
        o_.reuse_reference_patch ? ReferencePatchAt(ray, s0 + 0.5 * (count - 1), o_.patch_rows, ref) : nullptr;
    const float* ref_middle = ref_rows ? ref_rows + (o_.patch_rows / 2) * L : nullptr;
    // Choosing the reference point needs only the 2×5 patch on ℓ itself.
    SampleLine(ray, s0, count, line);
    for (int k = 0; k < count; ++k) {
      const double s = s0 + k;
      const ShiftMeasurement m = Measure(ray, s, 1, line->data() + k, true, ref_middle);
      if (!m.valid || std::abs(m.shift) > 2.0) continue;
      const double c = m.LogScore();
      if (c > best_c) {
        best_c = c;
        best_s = s;
        best = m;
      }
    }
    if (!std::isfinite(best_c)) return std::numeric_limits<double>::quiet_NaN();
    // Gauss-Newton on the shift, with the full patch_rows-row patch. C^c is
    // needed only at the final match: sampled once after the loop.
    double s = best_s + best.shift;
    bool moved = false;
    for (int it = 0; it < o_.shift_iterations; ++it) {
      const ShiftMeasurement m = Measure(ray, s, o_.patch_rows, nullptr, false, ref_rows);
      if (!m.valid || std::abs(m.shift) > 1.0) break;
      best = m;
      moved = true;
      s += m.shift;
      if (std::abs(m.shift) < o_.shift_tolerance_px) break;
    }
    if (moved) {
      // The last accepted measurement's match is at s (checked inside the image).
      const Eigen::Vector2d y = ray.Point(s);
      Eigen::Vector3f c;
      if (ray.pair->image_px.Sample3(y.x(), y.y(), &c))
        best.log_colour = -(c - ref_colour_).squaredNorm() * inv_two_sigma_c2_;
    }
    *best_out = best;
    return s;
  }


  // Σ C^c of the pixel's colour at depth d over the usable rays but `skip`,
  // summed in ray order; *views counts those rays. Every colour is sampled
  // before any exponential is taken: the samples are cache misses in as many
  // images as there are views, and they overlap this way instead of waiting in
  // turn behind exp calls (the same sum; sparse depth -4 % on 720p views).
  double ColourAgreement(const std::vector<EpipolarRay>& rays, const std::vector<char>& ray_ok, int skip, double d,
                         int* views) const {
    constexpr int kBatch = 32;
    float dist2[kBatch];
    int n = 0;
    double sum = 0;
    auto flush = [&] {
      for (int k = 0; k < n; ++k) sum += std::exp(-dist2[k] * inv_two_sigma_c2_);
      n = 0;
    };
    *views = 0;
    for (size_t g = 0; g < rays.size(); ++g) {
      if (!ray_ok[g] || static_cast<int>(g) == skip) continue;
      ++*views;
      const EpipolarRay& ray = rays[g];
      if (!ray.InFront(d)) continue;  // C^c = 0
      const Eigen::Vector2d y = ray.Pixel(d);
      Eigen::Vector3f c;
      if (!ray.pair->image_px.Sample3(y.x(), y.y(), &c)) continue;
      dist2[n++] = (c - ref_colour_).squaredNorm();
      if (n == kBatch) flush();
    }
    flush();
    return sum;
  }

 private:
  const GradientDepthOptions& o_;
  const FloatImage& ref_grey_;
  Eigen::Vector3f ref_colour_;
  int half_;
  double inv_two_sigma_c2_;
  bool avx2_ = false;  // four samples of a patch row at once (bit-identical)
};

// The per-pixel work of Estimate over rows [begin, end); returns the number of
// edge pixels. Built twice where the compiler can (GCC on x86-64, no
// sanitizer): for AVX2 and for the baseline x86-64, the copy chosen at run time
// from the CPU (an ifunc). FMA is deliberately not enabled in the AVX2 copy: a
// fused multiply-add rounds once where the baseline rounds twice, so both
// copies give the same floats (sparse_depth_bench --ref on the figurines).
// The AVX2 copy executes ~12 % fewer instructions (3-operand forms, fewer moves).
struct RowJob {
  const GradientDepthOptions& o;
  const std::vector<PairGeometry>& pairs;
  const std::vector<int>& first_level;
  const std::vector<int>& order;
  double d_near, d_far;
  const cv::Mat& grad;
  const cv::Mat& ref_smoothed;
  const FloatImage& ref_grey_px;
  const BoundingBox& volume;
  const PinholeView& vi;
  const BoundingBox* ray_box;  // edge pixels whose ray misses it are skipped; null: none
  DepthMap& out;
};

#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__) && \
    !defined(__SANITIZE_ADDRESS__) && !defined(__SANITIZE_THREAD__)
#define LFRECON_DEPTH_CLONES __attribute__((flatten, target_clones("avx2", "default")))
#else
#define LFRECON_DEPTH_CLONES
#endif

LFRECON_DEPTH_CLONES long long EstimateRows(const RowJob& job, int begin, int end) {
  const GradientDepthOptions& o = job.o;
  const std::vector<PairGeometry>& pairs = job.pairs;
  const std::vector<int>& first_level = job.first_level;
  const std::vector<int>& order = job.order;
  const double d_near = job.d_near, d_far = job.d_far;
  const int cols = job.grad.cols;
  const FloatImage& ref_grey_px = job.ref_grey_px;
  const BoundingBox& volume = job.volume;
  const PinholeView& vi = job.vi;
  DepthMap& out = job.out;
  const Eigen::Vector3d centre = vi.Center();
  long long num_edge = 0;
  std::vector<EpipolarRay> rays(pairs.size());
  std::vector<char> ray_ok(pairs.size());
  struct Candidate {
    double log_own;  // log C = log(C^c·C^d) in its own view; -inf once checked
    double d;
    int level;   // index into first_level
  };
  std::vector<Candidate> candidates;
  std::vector<float> line;
  for (int r = begin; r != end; ++r) {
    const float* grow = job.grad.ptr<float>(r);
    for (int c = 0; c < cols; ++c) {
      if (!(grow[c] > o.gradient_threshold)) continue;
      const Eigen::Vector2d p(c + 0.5, r + 0.5);
      // The pixel's ray; its parameter is the planar depth (dir reaches depth 1).
      const Eigen::Vector3d dir = vi.Unproject(p, 1.0) - centre;
      if (job.ray_box && !RayMeetsBox(centre, dir, *job.ray_box)) continue;
      ++num_edge;
      const Eigen::Vector3d ph(p.x(), p.y(), 1.0);
      // Planar depths at which this pixel's ray is inside V; empty when it never is.
      double v_in = 1, v_out = 0;
      if (o.settle_outside_volume && !RayBoxInterval(centre, dir, volume, &v_in, &v_out)) {
        v_in = std::numeric_limits<double>::infinity();  // never in V: settled at its first match
        v_out = -v_in;
      }
      const float* srow = job.ref_smoothed.ptr<float>(r);
      const Eigen::Vector3f colour(srow[3 * c], srow[3 * c + 1], srow[3 * c + 2]);
      PixelSolver solver(o, ref_grey_px, colour);
      for (size_t k = 0; k < pairs.size(); ++k) ray_ok[k] = rays[k].Init(pairs[k], ph);

      // Level 1: scan the whole depth range in the first-level views; a
      // candidate is scored by its own C and by C^c in the other first-level view.
      // Own C = C^c·C^d, times the mean colour agreement over every
      // neighbour: a repeated texture rarely agrees in all of them.
      // Agreement is at most 1, so candidates are checked in decreasing
      // order of their own C and the search stops once that cannot beat the
      // best: the same winner as checking all of them in scan order (the
      // first in scan order among equal scores), with a fraction of the checks.
      candidates.clear();
      for (size_t f = 0; f < first_level.size(); ++f) {
        const EpipolarRay& ray = rays[first_level[f]];
        if (!ray_ok[first_level[f]] || !ray.InFront(d_near)) continue;
        const double s_near = ray.S(d_near);
        const double s_far = ray.InFront(d_far) ? ray.S(d_far) : s_near + o.max_reference_points;
        const int count = std::min(o.max_reference_points, static_cast<int>(std::ceil(s_far - s_near)) + 1);
        if (count <= 0) continue;
        solver.SampleLine(ray, s_near, count, &line);
        // reuse_reference_patch: the reference side sampled once per block of
        // kScanBlock reference points, at the block's middle depth.
        constexpr int kScanBlock = 8;
        float ref_row[9];
        const float* ref = nullptr;
        for (int k = 0; k < count; ++k) {
          if (o.reuse_reference_patch && k % kScanBlock == 0)
            ref = solver.ReferencePatchAt(ray, s_near + k + 0.5 * (std::min(kScanBlock, count - k) - 1), 1, ref_row);
          const ShiftMeasurement m = solver.Measure(ray, s_near + k, 1, line.data() + k, true, ref);
          if (!m.valid || std::abs(m.shift) > 2.0) continue;
          const double d = ray.Depth(s_near + k + m.shift);
          if (!(d > 0)) continue;
          candidates.push_back({m.LogScore(), d, static_cast<int>(f)});
        }
      }
      double best_score = -1, best_depth = 0;
      int best_index = -1;
      constexpr double kChecked = -std::numeric_limits<double>::infinity();
      const int num_candidates = static_cast<int>(candidates.size());
      for (int checked = 0; checked < num_candidates; ++checked) {
        // Next unchecked candidate with the highest own score (earliest on ties).
        int q = -1;
        for (int k = 0; k < num_candidates; ++k)
          if (candidates[k].log_own > kChecked && (q < 0 || candidates[k].log_own > candidates[q].log_own)) q = k;
        if (q < 0) break;
        Candidate& cand = candidates[q];
        double score = std::exp(cand.log_own);
        if (score < best_score) break;
        cand.log_own = kChecked;
        if (score == best_score && q > best_index) continue;  // cannot win the tie
        int views_seen = 0;
        const double agree = solver.ColourAgreement(rays, ray_ok, first_level[cand.level], cand.d, &views_seen);
        if (views_seen > 0) score *= agree / views_seen;
        if (score > best_score || (score == best_score && q < best_index)) {
          best_score = score;
          best_depth = cand.d;
          best_index = q;
        }
      }
      if (best_score <= 0) continue;

      // All levels, nearest first: search around the prediction, refine the
      // shift, and fuse the views' depths weighted by their information.
      double depth = best_depth, sum_w = 0, sum_wd = 0;
      int tried = 0;
      struct ViewMatch {
        int k;
        double s, d, energy, c;
      };
      ViewMatch matches[64];
      int num_matches = 0;
      for (int k : order) {
        if (!ray_ok[k] || num_matches == 64) continue;
        const EpipolarRay& ray = rays[k];
        if (!ray.InFront(depth)) continue;
        ++tried;
        const double s_pred = ray.S(depth);
        const int K = o.refine_reference_points;
        ShiftMeasurement m;
        const double s = solver.Search(ray, s_pred - 0.5 * (K - 1), K, &m, &line);
        if (!std::isfinite(s) || std::abs(s - s_pred) > o.outlier_pixels) continue;
        const double d = ray.Depth(s);
        if (!(d > 0)) continue;
        const double slope = ray.dSdd(d);
        const double wgt = m.energy * slope * slope;
        sum_w += wgt;
        sum_wd += wgt * d;
        matches[num_matches++] = {k, s, d, m.energy, std::exp(m.LogScore())};
        depth = sum_wd / sum_w;
        if (o.settle_outside_volume) {
          // Depths within outlier_pixels of the prediction in this view;
          // Depth() <= 0 past the vanishing point means unbounded.
          const double s_now = ray.S(depth);
          const double lo = ray.Depth(s_now - o.outlier_pixels), hi = ray.Depth(s_now + o.outlier_pixels);
          const double lo_d = lo > 0 ? lo : 0, hi_d = hi > 0 ? hi : std::numeric_limits<double>::infinity();
          if (hi_d < v_in || lo_d > v_out) break;
        }
      }
      if (num_matches == 0 || !(depth > 0) || !std::isfinite(depth)) continue;
      // Final robust fit: views whose match is more than inlier_pixels from
      // the fused depth's prediction are dropped, and the rest refitted.
      double rms = 0, sum_c = 0;
      for (int round = 0; round < 2; ++round) {
        double w_sum = 0, wd_sum = 0, r2_sum = 0;
        sum_c = 0;
        int inliers = 0;
        for (int q = 0; q < num_matches; ++q) {
          const EpipolarRay& ray = rays[matches[q].k];
          const double res = ray.S(depth) - matches[q].s;
          if (std::abs(res) > o.inlier_pixels) continue;
          const double slope = ray.dSdd(matches[q].d);
          const double wgt = matches[q].energy * slope * slope;
          w_sum += wgt;
          wd_sum += wgt * matches[q].d;
          r2_sum += res * res;
          sum_c += matches[q].c;
          ++inliers;
        }
        if (inliers == 0) {
          depth = -1;
          break;
        }
        depth = wd_sum / w_sum;
        rms = std::sqrt(r2_sum / inliers);
      }
      if (!(depth > 0) || !std::isfinite(depth)) continue;
      // Confidence: colour/shift agreement of the inlier views over all views
      // tried (eq. 4-5), lowered when their matches scatter around the fit.
      const float conf = static_cast<float>(sum_c / std::max(tried, 1) *
                                            std::exp(-rms * rms / (2.0 * o.sigma_match * o.sigma_match)));
      out.depth.at<float>(r, c) = static_cast<float>(depth);
      out.confidence.at<float>(r, c) = conf;
      out.label.at<std::uint8_t>(r, c) = static_cast<std::uint8_t>(
          volume.Contains(vi.Unproject(p, depth)) ? DepthLabel::kForeground : DepthLabel::kBackground);
    }
  }
  return num_edge;
}

}  // namespace

GradientDepthEstimator::GradientDepthEstimator(const GradientDepthOptions& options) : options_(options) {
  options_.Check();
}

DepthMap GradientDepthEstimator::Estimate(const ViewImage& reference, const std::vector<const ViewImage*>& neighbors,
                                          const BoundingBox& volume) const {
  const GradientDepthOptions& o = options_;
  const PinholeView& vi = reference.view;
  DepthMap out(reference.image.rows, reference.image.cols);
  if (reference.image.empty() || reference.image.type() != CV_32FC3) {
    spdlog::warn("depth: reference image is empty or not CV_32FC3; no depth");
    return out;
  }

  // Patches are sampled from pre-smoothed images (see presmooth_sigma);
  // views that come without them are prepared here.
  std::deque<ViewImage> local;  // deque: pointers stay valid
  auto prepared = [&](const ViewImage& v) -> const ViewImage* {
    if (!v.smoothed.empty() && !v.grey.empty()) return &v;
    local.push_back(v);
    PrepareViewImage(&local.back(), o);
    return &local.back();
  };
  const ViewImage* ref_prepared = prepared(reference);
  std::vector<const ViewImage*> nb_prepared;
  for (const ViewImage* nb : neighbors)
    nb_prepared.push_back(nb && !nb->image.empty() && nb->image.type() == CV_32FC3 ? prepared(*nb) : nullptr);
  // The views the hierarchy uses (SelectHierarchyViews), and their pair
  // geometry in the order of use: pairs[0..first_level) are the first level.
  std::vector<const PinholeView*> nb_views;
  std::vector<char> nb_grid;
  for (const ViewImage* nb : nb_prepared) {
    nb_views.push_back(nb ? &nb->view : nullptr);
    nb_grid.push_back(nb ? nb->on_grid : 0);
  }
  const std::vector<int> selected = SelectHierarchyViews(vi, nb_views, nb_grid, o);
  std::vector<PairGeometry> pairs;
  for (int q : selected) {
    const ViewImage* nb = nb_prepared[q];
    PairGeometry pg;
    pg.view = nb;
    pg.image = &nb->smoothed;
    pg.grey = &nb->grey;
    pg.image_px = FloatImage(nb->smoothed);
    pg.grey_px = FloatImage(nb->grey);
    Eigen::Matrix3d R;
    Eigen::Vector3d t;
    RelativePose(vi, nb->view, &R, &t);
    pg.A = nb->view.K * R * vi.K_inv;
    pg.a = nb->view.K * t;
    pg.baseline = nb->view.Center() - vi.Center();
    pg.A_inv = pg.A.inverse();
    pg.g = pg.A_inv * pg.a;
    pg.r3 = pg.A_inv.row(2);
    pg.r3a = pg.r3.dot(pg.a);
    pg.angle_deg = AngleBetweenDeg(vi.ViewingDirection(), nb->view.ViewingDirection());
    pairs.push_back(pg);
  }
  if (pairs.empty()) {
    spdlog::warn("depth: no usable neighbour within {}°; empty depth map", o.max_view_angle_deg);
    return out;
  }
  std::vector<int> first_level = {0};
  if (pairs.size() > 1 && pairs[1].baseline.dot(pairs[0].baseline) < 0) first_level.push_back(1);
  std::vector<int> order;
  for (size_t k = 0; k < pairs.size(); ++k) order.push_back(static_cast<int>(k));

  // Search range from V.
  double d_near = o.min_depth, d_far = o.max_depth;
  if (d_far <= 0) {
    double zmin, zmax;
    PlanarDepthRange(vi, volume, &zmin, &zmax);
    if (!(zmax > 0)) {
      spdlog::warn("depth: V is behind the reference camera; empty depth map");
      return out;
    }
    d_near = std::max(0.5 * zmin, 1e-3);
    d_far = 20.0 * zmax;
  }
  d_near = std::max(d_near, 1e-6);
  spdlog::debug("depth: search range [{:.3f}, {:.3f}] m, {} neighbours", d_near, d_far, pairs.size());

  const cv::Mat grad = o.gradient_peak_fraction > 0 ? GradientPeaks(reference.image, o.gradient_peak_fraction)
                                                   : GradientMagnitude(reference.image);
  const FloatImage ref_grey_px(ref_prepared->grey);
  const int rows = reference.image.rows;
  std::atomic<long long> num_edge{0};

  const BoundingBox ray_box = volume.Grown(std::max(0.0, o.ray_margin) * volume.Extent().maxCoeff());
  const BoundingBox* cull = o.ray_margin >= 0 ? &ray_box : nullptr;
  const RowJob job{o, pairs, first_level, order, d_near, d_far, grad, ref_prepared->smoothed, ref_grey_px, volume, vi,
                   cull, out};
  tbb::parallel_for(tbb::blocked_range<int>(0, rows), [&](const tbb::blocked_range<int>& range) {
    num_edge += EstimateRows(job, range.begin(), range.end());
  });
  if (num_edge == 0)
    spdlog::warn("depth: no pixel with a gradient above g = {} looks towards V; empty depth map", o.gradient_threshold);
  return out;
}

}  // namespace lfrecon
