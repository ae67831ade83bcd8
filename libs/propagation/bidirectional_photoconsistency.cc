#include "propagation/bidirectional_photoconsistency.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <deque>
#include <opencv2/imgproc.hpp>

#include "util/error.h"

namespace lfrecon {

void PhotoconsistencyOptions::Check() const {
  LFRECON_CHECK_OPTION(sigma_p > 0);
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

// Bilinear sample of a CV_32FC3 image at COLMAP coordinates (pixel centres at
// +0.5), in single precision (the inner loop); false outside.
inline bool Sample3(const cv::Mat& image, float x, float y, Eigen::Vector3f* out) {
  const float fx = x - 0.5f, fy = y - 0.5f;
  if (!(fx >= 0.0f && fy >= 0.0f)) return false;  // also rejects NaN
  const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
  if (x0 + 1 >= image.cols || y0 + 1 >= image.rows) return false;
  const float ax = fx - x0, ay = fy - y0;
  const float* r0 = image.ptr<float>(y0) + 3 * x0;
  const float* r1 = image.ptr<float>(y0 + 1) + 3 * x0;
  const float w00 = (1 - ax) * (1 - ay), w01 = ax * (1 - ay), w10 = (1 - ax) * ay, w11 = ax * ay;
  for (int c = 0; c < 3; ++c) (*out)[c] = w00 * r0[c] + w01 * r0[3 + c] + w10 * r1[c] + w11 * r1[3 + c];
  return true;
}

// One neighbour: the homogeneous pixel of reference pixel x̃ on the plane at
// depth d is y = d·A·x̃ + a (A = K_j R_ji K_i⁻¹, a = K_j t_ji).
struct NeighborPair {
  const cv::Mat* image = nullptr;
  Eigen::Matrix3f A;
  Eigen::Vector3f a;
};

}  // namespace

BidirectionalPhotoconsistency::BidirectionalPhotoconsistency(const PhotoconsistencyOptions& options)
    : options_(options) {
  options_.Check();
}

EdgeConsistency BidirectionalPhotoconsistency::Compute(const ViewImage& reference,
                                                       const std::vector<const ViewImage*>& neighbors,
                                                       const DepthMap& depth) const {
  const PhotoconsistencyOptions& o = options_;
  const int rows = reference.image.rows, cols = reference.image.cols;
  EdgeConsistency out;
  out.c_plus = cv::Mat::zeros(rows, cols, CV_32F);
  out.c_minus = cv::Mat::zeros(rows, cols, CV_32F);
  out.direction = cv::Mat::zeros(rows, cols, CV_32FC2);
  out.evaluated = cv::Mat::zeros(rows, cols, CV_8U);
  if (reference.image.empty() || reference.image.type() != CV_32FC3 || depth.depth.empty() ||
      depth.depth.type() != CV_32F || depth.depth.size() != reference.image.size())
    return out;
  out.direction = GradientDirection(reference.image);

  std::deque<cv::Mat> local;  // smoothed copies made here (deque: stable references)
  auto source = [&](const ViewImage& v) -> const cv::Mat& {
    if (o.presmooth_sigma <= 0) return v.image;
    if (!v.smoothed.empty() && v.smoothed.size() == v.image.size() && v.smoothed.type() == CV_32FC3) return v.smoothed;
    local.emplace_back();
    cv::GaussianBlur(v.image, local.back(), cv::Size(0, 0), o.presmooth_sigma);
    return local.back();
  };
  const cv::Mat& ref_img = source(reference);
  const PinholeView& vi = reference.view;
  // Usable neighbours within the angle, by increasing angle.
  std::vector<std::pair<double, const ViewImage*>> usable;
  for (const ViewImage* nb : neighbors) {
    if (!nb || nb->image.empty() || nb->image.type() != CV_32FC3) continue;
    const double cosang = std::clamp(vi.ViewingDirection().dot(nb->view.ViewingDirection()), -1.0, 1.0);
    const double angle = std::acos(cosang) * 180.0 / M_PI;
    if (angle > o.max_view_angle_deg) continue;
    if ((nb->view.Center() - vi.Center()).norm() < 1e-9) continue;  // the reference itself
    usable.emplace_back(angle, nb);
  }
  std::stable_sort(usable.begin(), usable.end(),
                   [](const auto& x, const auto& y) { return x.first < y.first; });
  if (o.max_views > 0 && static_cast<int>(usable.size()) > o.max_views) {
    std::vector<std::pair<double, const ViewImage*>> kept;
    for (int k = 0; k < o.max_views; ++k)
      kept.push_back(usable[static_cast<std::size_t>(k) * usable.size() / o.max_views]);
    usable = kept;
  }
  std::vector<NeighborPair> pairs;
  for (const auto& [angle, nb] : usable) {
    Eigen::Matrix3d R;
    Eigen::Vector3d t;
    RelativePose(vi, nb->view, &R, &t);
    NeighborPair pair;
    pair.image = &source(*nb);
    pair.A = (nb->view.K * R * vi.K_inv).cast<float>();
    pair.a = (nb->view.K * t).cast<float>();
    pairs.push_back(pair);
  }
  if (pairs.empty()) return out;

  const int S = o.samples_per_side;
  const float step_px = static_cast<float>(o.sample_step_px);
  // exp(−‖f − g‖² / (2σ_p²)) (eq. 9), ‖·‖² per sample pixel (see header).
  const float inv_two_sigma2 = static_cast<float>(1.0 / (2.0 * o.sigma_p * o.sigma_p * S));
  tbb::parallel_for(tbb::blocked_range<int>(0, rows), [&](const tbb::blocked_range<int>& range) {
    std::vector<Eigen::Vector3f> f(2 * S);  // f+ then f−
    for (int r = range.begin(); r != range.end(); ++r) {
      const float* drow = depth.depth.ptr<float>(r);
      const cv::Vec2f* dir = out.direction.ptr<cv::Vec2f>(r);
      float* cplus = out.c_plus.ptr<float>(r);
      float* cminus = out.c_minus.ptr<float>(r);
      std::uint8_t* ev = out.evaluated.ptr<std::uint8_t>(r);
      for (int c = 0; c < cols; ++c) {
        const float d = drow[c];
        if (!(d > 0) || !std::isfinite(d)) continue;
        const cv::Vec2f n = dir[c];
        if (n[0] == 0 && n[1] == 0) continue;
        ev[c] = 255;
        const Eigen::Vector2f p(c + 0.5f, r + 0.5f);
        const Eigen::Vector2f step = step_px * Eigen::Vector2f(n[0], n[1]);
        // Reference samples f+ (at p + k·step) and f− (at p − k·step).
        bool side_ok[2] = {true, true};
        for (int side = 0; side < 2; ++side) {
          const float sgn = side == 0 ? 1.0f : -1.0f;
          for (int k = 1; k <= S && side_ok[side]; ++k) {
            const Eigen::Vector2f x = p + (sgn * k) * step;
            side_ok[side] = Sample3(ref_img, x.x(), x.y(), &f[side * S + k - 1]);
          }
        }
        if (!side_ok[0] && !side_ok[1]) continue;
        // Through the plane at d: y(x) = d·A·x̃ + a is linear in x, so step along θ.
        float sum_rho[2] = {0, 0};
        int count[2] = {0, 0};
        for (const NeighborPair& pair : pairs) {
          const Eigen::Vector3f y0 = d * (pair.A * Eigen::Vector3f(p.x(), p.y(), 1.0f)) + pair.a;
          const Eigen::Vector3f dy = d * (pair.A.leftCols<2>() * step);
          for (int side = 0; side < 2; ++side) {
            if (!side_ok[side]) continue;
            const float sgn = side == 0 ? 1.0f : -1.0f;
            float ssd = 0;
            bool ok = true;
            for (int k = 1; k <= S; ++k) {
              const Eigen::Vector3f y = y0 + (sgn * k) * dy;
              Eigen::Vector3f g;
              if (!(y.z() > 0) || !Sample3(*pair.image, y.x() / y.z(), y.y() / y.z(), &g)) {
                ok = false;
                break;
              }
              ssd += (f[side * S + k - 1] - g).squaredNorm();
            }
            if (!ok) continue;
            sum_rho[side] += std::exp(-ssd * inv_two_sigma2);
            ++count[side];
          }
        }
        // C+(p), C−(p): averages over the views (§4.1).
        cplus[c] = count[0] ? sum_rho[0] / count[0] : 0.0f;
        cminus[c] = count[1] ? sum_rho[1] / count[1] : 0.0f;
      }
    }
  });
  return out;
}

}  // namespace lfrecon
