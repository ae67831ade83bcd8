#include "eval/depth_metrics.h"

#include <algorithm>
#include <cmath>

#include "depth/gradient_depth_estimator.h"
#include "util/error.h"

namespace lfrecon {

void DepthMetricsOptions::Check() const {
  LFRECON_CHECK_OPTION(relative_tolerance > 0);
  LFRECON_CHECK_OPTION(gradient_threshold >= 0);
  LFRECON_CHECK_OPTION(volume_margin >= 0);
}

void DepthMetrics::Add(const DepthMetrics& other) {
  expected += other.expected;
  estimated += other.estimated;
  accurate += other.accurate;
  samples.insert(samples.end(), other.samples.begin(), other.samples.end());
}

DepthMetrics EvaluateDepth(const DepthMap& estimate, const cv::Mat& true_depth, const cv::Mat& image,
                           const PinholeView& view, const BoundingBox& volume, const DepthMetricsOptions& options) {
  options.Check();
  DepthMetrics m;
  BoundingBox inner = volume;
  inner.min.array() += options.volume_margin;
  inner.max.array() -= options.volume_margin;
  cv::Mat grad;
  if (!options.dense) grad = GradientMagnitude(image);
  for (int r = 0; r < true_depth.rows; ++r) {
    for (int c = 0; c < true_depth.cols; ++c) {
      const float t = true_depth.at<float>(r, c);
      if (!(t > 0) || !std::isfinite(t)) continue;
      if (!inner.Contains(view.Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), t))) continue;
      if (!options.dense && !(grad.at<float>(r, c) > options.gradient_threshold)) continue;
      ++m.expected;
      const float e = estimate.depth.at<float>(r, c);
      if (!(e > 0)) continue;
      ++m.estimated;
      const bool ok = std::abs(e - t) <= options.relative_tolerance * t;
      m.accurate += ok;
      m.samples.emplace_back(estimate.confidence.empty() ? 1.0f : estimate.confidence.at<float>(r, c), ok);
    }
  }
  return m;
}

std::vector<CurvePoint> AccuracyCoverageCurve(const DepthMetrics& metrics, int num_points) {
  std::vector<CurvePoint> curve;
  if (metrics.samples.empty() || metrics.expected == 0) return curve;
  std::vector<std::pair<float, bool>> s = metrics.samples;
  std::sort(s.begin(), s.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
  long long accurate = 0;
  size_t next = 0;
  for (int q = 1; q <= num_points; ++q) {
    const size_t upto = std::max<size_t>(1, s.size() * q / num_points);
    for (; next < upto; ++next) accurate += s[next].second;
    CurvePoint p;
    p.min_confidence = s[upto - 1].first;
    p.accuracy = static_cast<double>(accurate) / upto;
    p.coverage = static_cast<double>(upto) / metrics.expected;
    curve.push_back(p);
  }
  return curve;
}

}  // namespace lfrecon
