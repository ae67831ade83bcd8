#include "propagation/bidirectional_photoconsistency.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "propagation/colour_difference.h"
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

// The homogeneous pixel of reference pixel x̃ in a neighbour, on the plane at
// depth d: y = d·A·x̃ + a (A = K_j R_ji K_i⁻¹, a = K_j t_ji).
struct NeighborPair {
  Eigen::Matrix3f A;
  Eigen::Vector3f a;
};

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
  pixels_.clear();
  samples_.clear();
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

  const int S = o.samples_per_side;
  const float step_px = static_cast<float>(o.sample_step_px);
  std::vector<Eigen::Vector3f> f(2 * S + 3);  // f+ then f−, then C0's samples along the edge
  for (int r = 0; r < rows; ++r) {
    const float* drow = depth.depth.ptr<float>(r);
    const cv::Vec2f* dir = out_.direction.ptr<cv::Vec2f>(r);
    for (int c = 0; c < cols; ++c) {
      const float d = drow[c];
      if (!(d > 0) || !std::isfinite(d)) continue;
      const cv::Vec2f n = dir[c];
      if (n[0] == 0 && n[1] == 0) continue;
      out_.evaluated.at<std::uint8_t>(r, c) = 255;
      Pixel px;
      px.row = r;
      px.col = c;
      px.d = d;
      const Eigen::Vector2f p(c + 0.5f, r + 0.5f);
      const Eigen::Vector2f step = step_px * Eigen::Vector2f(n[0], n[1]);
      px.px = p.x();
      px.py = p.y();
      px.sx = step.x();
      px.sy = step.y();
      // Reference samples f+ (at p + k·step) and f− (at p − k·step).
      for (int side = 0; side < 2; ++side) {
        const float sgn = side == 0 ? 1.0f : -1.0f;
        for (int k = 1; k <= S && px.side_ok[side]; ++k) {
          const Eigen::Vector2f x = p + (sgn * k) * step;
          px.side_ok[side] = SampleBgr(ref_img, x.x(), x.y(), &f[side * S + k - 1]);
        }
      }
      if (!px.side_ok[0] && !px.side_ok[1]) continue;
      if (o.centre_consistency) {  // p − t, p, p + t with t ⊥ θ(p)
        const Eigen::Vector2f t(-step.y(), step.x());
        px.centre_ok = true;
        for (int k = -1; k <= 1 && px.centre_ok; ++k) {
          const Eigen::Vector2f x = p + static_cast<float>(k) * t;
          px.centre_ok = SampleBgr(ref_img, x.x(), x.y(), &f[2 * S + k + 1]);
        }
      }
      pixels_.push_back(px);
      for (int k = 0; k < 2 * S; ++k)
        for (int ch = 0; ch < 3; ++ch) samples_.push_back(px.side_ok[k / S] ? f[k][ch] : 0.0f);
      if (o.centre_consistency)
        for (int k = 0; k < 3; ++k)
          for (int ch = 0; ch < 3; ++ch) samples_.push_back(px.centre_ok ? f[2 * S + k][ch] : 0.0f);
    }
  }
}

void PhotoconsistencyAccumulator::Add(const ViewImage& neighbor) {
  const PhotoconsistencyOptions& o = options_;
  if (!valid_ || !UsableImage(&neighbor)) return;
  if (UsableAngle(reference_view_, neighbor.view, o.max_view_angle_deg) < 0) return;
  ++added_;
  if (pixels_.empty()) return;
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  RelativePose(reference_view_, neighbor.view, &R, &t);
  NeighborPair pair;
  pair.A = (neighbor.view.K * R * reference_view_.K_inv).cast<float>();
  pair.a = (neighbor.view.K * t).cast<float>();
  cv::Mat local;
  const cv::Mat& image = SourceImage(neighbor, o, &local);

  const int S = o.samples_per_side;
  // exp(−‖f − g‖² / (2σ_p²)) (eq. 9), ‖·‖² per sample pixel (see header).
  const float inv_two_sigma2 = static_cast<float>(1.0 / (2.0 * o.sigma_p * o.sigma_p * S));
  const std::size_t per_pixel = static_cast<std::size_t>(6 * S + (o.centre_consistency ? 9 : 0));
  const float inv_two_sigma2_centre = static_cast<float>(1.0 / (2.0 * o.sigma_p * o.sigma_p * 3));
  // Σ‖f − g‖² (chroma weighted: ColourDifference2) of n samples at
  // y0 + (first + i·step)·dy (i = 0..n−1) in the neighbour against the
  // reference's at `ref` (3 floats each); false when a sample leaves the neighbour.
  const float chroma_weight = static_cast<float>(o.chroma_weight);
  const auto ssd_along = [&image, chroma_weight](const Eigen::Vector3f& y0, const Eigen::Vector3f& dy, int first, int step, int n,
                                  const float* ref, float* ssd) {
    *ssd = 0;
    for (int i = 0; i < n; ++i) {
      const Eigen::Vector3f y = y0 + static_cast<float>(first + i * step) * dy;
      Eigen::Vector3f g;
      if (!(y.z() > 0) || !SampleBgr(image, y.x() / y.z(), y.y() / y.z(), &g)) return false;
      const float* fk = ref + 3 * i;
      *ssd += ColourDifference2(Eigen::Vector3f(fk[0], fk[1], fk[2]), g, chroma_weight);
    }
    return true;
  };
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, pixels_.size(), 256),
                    [&](const tbb::blocked_range<std::size_t>& range) {
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      Pixel& px = pixels_[i];
      const float* fs = samples_.data() + i * per_pixel;
      const float d = px.d;
      // Through the plane at d: y(x) = d·A·x̃ + a is linear in x, so step along θ.
      const Eigen::Vector3f y0 = d * (pair.A * Eigen::Vector3f(px.px, px.py, 1.0f)) + pair.a;
      const Eigen::Vector3f dy = d * (pair.A.leftCols<2>() * Eigen::Vector2f(px.sx, px.sy));
      for (int side = 0; side < 2; ++side) {
        if (!px.side_ok[side]) continue;
        const int sgn = side == 0 ? 1 : -1;  // samples at p ± k·step, k = 1..S
        float ssd;
        if (!ssd_along(y0, dy, sgn, sgn, S, fs + 3 * side * S, &ssd)) continue;
        px.sum_rho[side] += std::exp(-ssd * inv_two_sigma2);
        ++px.count[side];
      }
      if (px.centre_ok) {  // samples at p + k·t, k = −1, 0, 1, t ⊥ θ(p)
        const Eigen::Vector3f dt = d * (pair.A.leftCols<2>() * Eigen::Vector2f(-px.sy, px.sx));
        float ssd;
        if (ssd_along(y0, dt, -1, 1, 3, fs + 6 * S, &ssd)) {
          px.sum_centre += std::exp(-ssd * inv_two_sigma2_centre);
          ++px.count_centre;
        }
      }
    }
  });
}

EdgeConsistency PhotoconsistencyAccumulator::Finish() {
  // Evaluated: every pixel with depth and a direction, once a neighbour took part.
  if (added_ == 0) {
    out_.evaluated.setTo(0);
  } else {
    for (const Pixel& px : pixels_) {
      // C+(p), C−(p): averages over the views (§4.1).
      out_.c_plus.at<float>(px.row, px.col) = px.count[0] ? px.sum_rho[0] / px.count[0] : 0.0f;
      out_.c_minus.at<float>(px.row, px.col) = px.count[1] ? px.sum_rho[1] / px.count[1] : 0.0f;
      if (!out_.c_centre.empty())
        out_.c_centre.at<float>(px.row, px.col) = px.count_centre ? px.sum_centre / px.count_centre : 0.0f;
    }
  }
  EdgeConsistency result = std::move(out_);
  out_ = EdgeConsistency();
  pixels_.clear();
  pixels_.shrink_to_fit();
  samples_.clear();
  samples_.shrink_to_fit();
  valid_ = false;
  added_ = 0;
  return result;
}

}  // namespace lfrecon
