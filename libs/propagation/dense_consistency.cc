#include "propagation/dense_consistency.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

#include "propagation/image_sampling.h"
#include "propagation/neighbor_views.h"
#include "util/error.h"

namespace lfrecon {

void DenseConsistencyOptions::Check() const {
  LFRECON_CHECK_OPTION(sigma > 0);
  LFRECON_CHECK_OPTION(views >= 0);
  LFRECON_CHECK_OPTION(patch_radius_px >= 0 && patch_radius_px <= 3);
  LFRECON_CHECK_OPTION(rho_min >= 0 && rho_min <= 1);
  LFRECON_CHECK_OPTION(max_view_angle_deg > 0 && max_view_angle_deg < 90);
  LFRECON_CHECK_OPTION(ncc_radius_px >= 0 && ncc_radius_px <= 7);
  LFRECON_CHECK_OPTION(ncc_min >= -1 && ncc_min <= 1);
  LFRECON_CHECK_OPTION(ncc_texture_min > 0);
}

DenseConsistencyAccumulator::DenseConsistencyAccumulator(const DenseConsistencyOptions& options)
    : options_(options) {
  options_.Check();
}

std::vector<int> DenseConsistencyAccumulator::SelectNeighbors(
    const PinholeView& reference, const std::vector<const PinholeView*>& neighbors) const {
  return WidestNeighbors(reference, neighbors, options_.max_view_angle_deg, options_.views);
}

namespace {

// Mean colour over (2r+1)² pixels at every pixel (CV_32FC3).
cv::Mat PatchMeans(const cv::Mat& bgr, int r) {
  if (r <= 0) return bgr;
  cv::Mat out;
  cv::blur(bgr, out, cv::Size(2 * r + 1, 2 * r + 1), cv::Point(-1, -1), cv::BORDER_REPLICATE);
  return out;
}

}  // namespace

void DenseConsistencyAccumulator::Begin(const ViewImage& reference, const DepthMap& dense, const cv::Mat& own) {
  pixels_.clear();
  reference_view_ = reference.view;
  size_ = dense.depth.size();
  if (dense.depth.empty() || dense.depth.type() != CV_32F || reference.image.size() != dense.depth.size() ||
      reference.image.type() != CV_32FC3 || dense.label.size() != dense.depth.size())
    return;
  const cv::Mat means = PatchMeans(PhotometricColours(reference), options_.patch_radius_px);
  const bool skip_own = own.size() == dense.depth.size() && own.type() == CV_32F;
  const int nr = options_.ncc_radius_px;
  cv::Mat grey_mean, grey_sq_mean;
  reference_grey_.release();
  if (nr > 0) {
    reference_grey_ = PhotometricGrey(reference);
    const cv::Size k(2 * nr + 1, 2 * nr + 1);
    cv::blur(reference_grey_, grey_mean, k, cv::Point(-1, -1), cv::BORDER_REPLICATE);
    cv::blur(reference_grey_.mul(reference_grey_), grey_sq_mean, k, cv::Point(-1, -1), cv::BORDER_REPLICATE);
  }
  constexpr std::uint8_t kFg = static_cast<std::uint8_t>(DepthLabel::kForeground);
  for (int r = 0; r < dense.depth.rows; ++r) {
    const float* d = dense.depth.ptr<float>(r);
    const std::uint8_t* l = dense.label.ptr<std::uint8_t>(r);
    const float* o = skip_own ? own.ptr<float>(r) : nullptr;
    const float* m = means.ptr<float>(r);
    for (int c = 0; c < dense.depth.cols; ++c) {
      if (!(d[c] > 0) || l[c] != kFg || (o && o[c] > 0)) continue;
      Pixel p;
      p.row = r;
      p.col = c;
      p.d = d[c];
      for (int k = 0; k < 3; ++k) p.colour[k] = m[3 * c + k];
      if (nr > 0 && r >= nr && c >= nr && r + nr < dense.depth.rows && c + nr < dense.depth.cols) {
        const float mu = grey_mean.at<float>(r, c);
        const float sd = std::sqrt(std::max(0.0f, grey_sq_mean.at<float>(r, c) - mu * mu));
        p.textured = sd >= options_.ncc_texture_min;
        p.grey_mean = mu;
        p.grey_std = sd;
      }
      pixels_.push_back(p);
    }
  }
}

void DenseConsistencyAccumulator::Add(const ViewImage& neighbor) {
  if (pixels_.empty() || !UsableImage(&neighbor)) return;
  // The neighbour's patch means sampled at the projection of the pixel's
  // centre: at ≤ 5° the plane's mapping is locally a translation, so this is
  // the mean over the mapped patch, for one bilinear sample instead of (2r+1)².
  const cv::Mat means = PatchMeans(PhotometricColours(neighbor), options_.patch_radius_px);
  const int side = SideOf(reference_view_, neighbor.view);
  // A reference pixel x̃ on the plane fronto-parallel to the reference at
  // depth d lands at y = d·A·x̃ + a in the neighbour (A = K_j R_ji K_i⁻¹, a = K_j t_ji).
  Eigen::Matrix3d R_ji;
  Eigen::Vector3d t_ji;
  RelativePose(reference_view_, neighbor.view, &R_ji, &t_ji);
  const Eigen::Matrix3f A = (neighbor.view.K * R_ji * reference_view_.K_inv).cast<float>();
  const Eigen::Vector3f a = (neighbor.view.K * t_ji).cast<float>();
  const float margin = static_cast<float>(options_.patch_radius_px);
  const float max_x = static_cast<float>(means.cols) - margin, max_y = static_cast<float>(means.rows) - margin;
  const float inv2s2 = static_cast<float>(1.0 / (2.0 * options_.sigma * options_.sigma));
  const int nr = options_.ncc_radius_px;
  const cv::Mat grey = nr > 0 ? PhotometricGrey(neighbor) : cv::Mat();
  const float n_samples = static_cast<float>((2 * nr + 1) * (2 * nr + 1));
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, pixels_.size(), 4096),
                    [&](const tbb::blocked_range<std::size_t>& range) {
                      for (std::size_t i = range.begin(); i != range.end(); ++i) {
                        Pixel& p = pixels_[i];
                        const Eigen::Vector3f y = p.d * (A * Eigen::Vector3f(p.col + 0.5f, p.row + 0.5f, 1.0f)) + a;
                        if (!(y.z() > 0)) continue;
                        const float u = y.x() / y.z(), v = y.y() / y.z();
                        // The whole patch must land inside the neighbour.
                        if (!(u >= margin && v >= margin && u <= max_x && v <= max_y)) continue;
                        Eigen::Vector3f g;
                        if (!SampleBgr(means, u, v, &g)) continue;
                        float e = 0;
                        for (int k = 0; k < 3; ++k) e += (g[k] - p.colour[k]) * (g[k] - p.colour[k]);
                        p.sum[side] += std::exp(-e * inv2s2);
                        ++p.count[side];
                        if (!p.textured) continue;
                        // ZNCC of the (2r+1)² patches, the neighbour's sampled
                        // bilinearly around y (the same sub-pixel weights for all).
                        const float fx = u - 0.5f - nr, fy = v - 0.5f - nr;
                        if (!(fx >= 0 && fy >= 0)) continue;
                        const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
                        if (x0 + 2 * nr + 1 >= grey.cols || y0 + 2 * nr + 1 >= grey.rows) continue;
                        const float ax = fx - x0, ay = fy - y0;
                        const float w00 = (1 - ax) * (1 - ay), w01 = ax * (1 - ay), w10 = (1 - ax) * ay, w11 = ax * ay;
                        float sg = 0, sgg = 0, srg = 0;
                        for (int dy = 0; dy <= 2 * nr; ++dy) {
                          const float* g0 = grey.ptr<float>(y0 + dy) + x0;
                          const float* g1 = grey.ptr<float>(y0 + dy + 1) + x0;
                          const float* rr = reference_grey_.ptr<float>(p.row - nr + dy) + (p.col - nr);
                          for (int dx = 0; dx <= 2 * nr; ++dx) {
                            const float gv = w00 * g0[dx] + w01 * g0[dx + 1] + w10 * g1[dx] + w11 * g1[dx + 1];
                            sg += gv;
                            sgg += gv * gv;
                            srg += rr[dx] * gv;
                          }
                        }
                        const float mg = sg / n_samples;
                        const float var_g = std::max(0.0f, sgg / n_samples - mg * mg);
                        const float cov = srg / n_samples - p.grey_mean * mg;
                        const float ncc = var_g > 1e-12f ? cov / (p.grey_std * std::sqrt(var_g)) : 0.0f;
                        p.ncc_sum[side] += ncc;
                        ++p.ncc_count[side];
                      }
                    });
}

cv::Mat DenseConsistencyAccumulator::Finish() {
  cv::Mat rho(size_, CV_32F, cv::Scalar(-1.0f));
  for (const Pixel& p : pixels_) {
    float best = -1;
    for (int s = 0; s < 2; ++s)
      if (p.count[s] > 0) best = std::max(best, p.sum[s] / p.count[s]);
    if (p.textured && best >= 0) {
      // The texture test fails: reported as ρ = 0, so the pixel is rejected like a low ρ.
      float best_ncc = -2;
      for (int s = 0; s < 2; ++s)
        if (p.ncc_count[s] > 0) best_ncc = std::max(best_ncc, p.ncc_sum[s] / p.ncc_count[s]);
      if (best_ncc > -2 && best_ncc < options_.ncc_min) best = 0;
    }
    rho.at<float>(p.row, p.col) = best;
  }
  pixels_.clear();
  return rho;
}

void ApplyDenseConsistency(const cv::Mat& rho, double rho_min, DepthMap* dense) {
  if (rho.size() != dense->depth.size()) return;
  const bool has_confidence = dense->confidence.size() == dense->depth.size();
  const bool has_label = dense->label.size() == dense->depth.size();
  for (int r = 0; r < rho.rows; ++r) {
    const float* q = rho.ptr<float>(r);
    for (int k = 0; k < rho.cols; ++k) {
      if (q[k] < 0 || q[k] >= rho_min) continue;
      dense->depth.at<float>(r, k) = 0;
      if (has_confidence) dense->confidence.at<float>(r, k) = 0;
      if (has_label) dense->label.at<std::uint8_t>(r, k) = static_cast<std::uint8_t>(DepthLabel::kNone);
    }
  }
}

void CheckDenseConsistency(const ViewImage& reference, const std::vector<const ViewImage*>& neighbors,
                           const DenseConsistencyOptions& options, DepthMap* dense, const cv::Mat& own) {
  if (options.views <= 0) return;
  const UsableNeighbors usable = FindUsableNeighbors(neighbors);
  DenseConsistencyAccumulator acc(options);
  acc.Begin(reference, *dense, own);
  for (int j : acc.SelectNeighbors(reference.view, usable.views)) acc.Add(*usable.images[static_cast<std::size_t>(j)]);
  ApplyDenseConsistency(acc.Finish(), options.rho_min, dense);
}

}  // namespace lfrecon
