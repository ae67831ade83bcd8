#include "propagation/photometric_refinement.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>

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

std::vector<int> PhotometricRefinementAccumulator::SelectNeighbors(
    const PinholeView& reference, const std::vector<const PinholeView*>& neighbors) const {
  return WidestNeighbors(reference, neighbors, options_.max_view_angle_deg, options_.views);
}

namespace {

// Grey levels (CV_32F) of the frame the photometric checks read: `smoothed`
// when present (its own `grey` when that matches), else `image`.
cv::Mat GreyOf(const ViewImage& v) {
  const bool smoothed = !v.smoothed.empty() && v.smoothed.size() == v.image.size() && v.smoothed.type() == CV_32FC3;
  if (smoothed && v.grey.size() == v.smoothed.size() && v.grey.type() == CV_32F) return v.grey;
  cv::Mat grey;
  cv::cvtColor(smoothed ? v.smoothed : v.image, grey, cv::COLOR_BGR2GRAY);
  return grey;
}

// Bilinear grey sample at COLMAP coordinates (pixel centres at +0.5); the
// caller has checked that (x, y) lies inside.
inline float SampleGrey(const cv::Mat& grey, float x, float y) {
  const float fx = x - 0.5f, fy = y - 0.5f;
  const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
  const float ax = fx - x0, ay = fy - y0;
  const float* r0 = grey.ptr<float>(y0) + x0;
  const float* r1 = grey.ptr<float>(y0 + 1) + x0;
  return (1 - ay) * ((1 - ax) * r0[0] + ax * r0[1]) + ay * ((1 - ax) * r1[0] + ax * r1[1]);
}

}  // namespace

void PhotometricRefinementAccumulator::Begin(const ViewImage& reference, const DepthMap& dense,
                                             const std::vector<const PinholeView*>& selected, const cv::Mat& keep) {
  reference_view_ = reference.view;
  rows_ = dense.depth.rows;
  cols_ = dense.depth.cols;
  pixels_.clear();
  zeta0_.clear();
  ref_patch_.clear();
  ref_norm_.clear();
  scores_.clear();
  counts_.clear();
  zeta_step_ = 0;
  if (options_.views <= 0 || dense.depth.empty() || reference.image.size() != dense.depth.size()) return;
  // The widest baseline's shift per unit inverse depth is about f·B.
  double baseline = 0;
  for (const PinholeView* v : selected)
    if (v) baseline = std::max(baseline, (v->Center() - reference.view.Center()).norm());
  if (baseline <= 0) return;
  zeta_step_ = options_.step_px / (reference.view.K(0, 0) * baseline);

  cv::Mat keep_mask;
  if (!keep.empty() && keep.size() == dense.depth.size()) keep_mask = keep != 0;
  const cv::Mat grey = GreyOf(reference);
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
      pixels_.push_back(y * cols_ + x);
      zeta0_.push_back(1.0f / d[x]);
      ref_patch_.insert(ref_patch_.end(), patch.begin(), patch.end());
      ref_norm_.push_back(std::sqrt(ss));
    }
  }
  scores_.assign(pixels_.size() * static_cast<std::size_t>(2 * options_.steps + 1), 0.0f);
  counts_.assign(pixels_.size(), 0);
}

void PhotometricRefinementAccumulator::Add(const ViewImage& neighbor) {
  if (pixels_.empty() || !UsableImage(&neighbor)) return;
  const cv::Mat grey = GreyOf(neighbor);
  // x_j ~ K_j (R_rel · d K_ref⁻¹ p + t_rel) ∝ M p + ζ e with ζ = 1/d: linear in
  // the pixel and in the inverse depth.
  const PinholeView& ref = reference_view_;
  const PinholeView& nb = neighbor.view;
  const Eigen::Matrix3d r_rel = nb.R * ref.R.transpose();
  const Eigen::Vector3d t_rel = nb.t - r_rel * ref.t;
  const Eigen::Matrix3f m = (nb.K * r_rel * ref.K_inv).cast<float>();
  const Eigen::Vector3f e = (nb.K * t_rel).cast<float>();
  const int r = options_.patch_radius_px, n = (2 * r + 1) * (2 * r + 1);
  const int hyps = 2 * options_.steps + 1;
  const float zeta_step = static_cast<float>(zeta_step_);
  // Samples must fall where the bilinear 2x2 is inside: [0.5, size - 0.5).
  const float x_max = static_cast<float>(grey.cols) - 0.5f - 1e-3f, y_max = static_cast<float>(grey.rows) - 0.5f - 1e-3f;
  const Eigen::Vector3f m0 = m.col(0), m1 = m.col(1);

  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, pixels_.size(), 256), [&](const tbb::blocked_range<std::size_t>& range) {
    std::vector<float> samples(static_cast<std::size_t>(n * hyps));
    for (std::size_t i = range.begin(); i != range.end(); ++i) {
      const int px = pixels_[i] % cols_, py = pixels_[i] / cols_;
      const Eigen::Vector3f centre =
          m * Eigen::Vector3f(static_cast<float>(px) + 0.5f, static_cast<float>(py) + 0.5f, 1.0f) + zeta0_[i] * e;
      // Every sample of every hypothesis inside the frame and in front of it, or the view is skipped for this pixel.
      bool inside = true;
      for (int k = 0; k < hyps && inside; k += hyps - 1) {
        const Eigen::Vector3f h0 = centre + (static_cast<float>(k - options_.steps) * zeta_step) * e;
        for (int corner = 0; corner < 4 && inside; ++corner) {
          const float a = (corner & 1) ? static_cast<float>(r) : -static_cast<float>(r);
          const float b = (corner & 2) ? static_cast<float>(r) : -static_cast<float>(r);
          const Eigen::Vector3f h = h0 + a * m0 + b * m1;
          if (!(h.z() > 0)) {
            inside = false;
            break;
          }
          const float x = h.x() / h.z(), y = h.y() / h.z();
          if (!(x >= 0.5f && x < x_max && y >= 0.5f && y < y_max)) inside = false;
        }
      }
      if (!inside) continue;
      const float* ref_patch = &ref_patch_[i * static_cast<std::size_t>(n)];
      float* score = &scores_[i * static_cast<std::size_t>(hyps)];
      for (int k = 0; k < hyps; ++k) {
        // Over a patch of a few pixels at <= 5° the plane's homography is affine
        // to well under a hundredth of a pixel: positions = centre + a·J0 + b·J1.
        const Eigen::Vector3f h0 = centre + (static_cast<float>(k - options_.steps) * zeta_step) * e;
        const float inv0 = 1.0f / h0.z();
        const float cx = h0.x() * inv0, cy = h0.y() * inv0;
        const float j0x = (m0.x() - cx * m0.z()) * inv0, j0y = (m0.y() - cy * m0.z()) * inv0;
        const float j1x = (m1.x() - cx * m1.z()) * inv0, j1y = (m1.y() - cy * m1.z()) * inv0;
        float sum = 0, sum_sq = 0, cross = 0;
        int s = 0;
        for (int b = -r; b <= r; ++b) {
          float x = cx - static_cast<float>(r) * j0x + static_cast<float>(b) * j1x;
          float y = cy - static_cast<float>(r) * j0y + static_cast<float>(b) * j1y;
          for (int a = -r; a <= r; ++a, ++s, x += j0x, y += j0y) {
            const float v = SampleGrey(grey, x, y);
            sum += v;
            sum_sq += v * v;
            cross += v * ref_patch[s];  // the reference patch is zero-mean: Σ(v − μ)·p = Σ v·p
          }
        }
        const float var = sum_sq - sum * sum / static_cast<float>(n);
        score[k] += var > 1e-12f ? cross / (std::sqrt(var) * ref_norm_[i]) : 0.0f;
      }
      ++counts_[i];
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
    dense->depth.at<float>(pixels_[i] / cols_, pixels_[i] % cols_) = 1.0f / zeta;
    ++changed;
  }
  return changed;
}

int RefineDepthPhotometrically(const ViewImage& reference, const std::vector<const ViewImage*>& neighbors,
                               const PhotometricRefinementOptions& options, DepthMap* dense, const cv::Mat& keep) {
  if (options.views <= 0) return 0;
  const UsableNeighbors usable = FindUsableNeighbors(neighbors);
  PhotometricRefinementAccumulator acc(options);
  const std::vector<int> chosen = acc.SelectNeighbors(reference.view, usable.views);
  std::vector<const PinholeView*> selected;
  for (int j : chosen) selected.push_back(usable.views[static_cast<std::size_t>(j)]);
  acc.Begin(reference, *dense, selected, keep);
  for (int j : chosen) acc.Add(*usable.images[static_cast<std::size_t>(j)]);
  return acc.Finish(dense);
}

}  // namespace lfrecon
