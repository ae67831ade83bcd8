#pragma once
// Depth-map quality against ground truth (BRIEF §4): over ground-truth
// foreground pixels (true depth inside V), accuracy = share of estimates within
// a relative tolerance (0.5 %) of the true depth, coverage = share of the
// pixels that should have an estimate which got one. For sparse maps "should"
// means ‖∇I‖ > g; for dense maps, every ground-truth foreground pixel.
#include <vector>

#include "depth/depth_map.h"
#include "geometry/pinhole_view.h"
#include "geometry/triangle_mesh.h"

namespace lfrecon {

struct DepthMetricsOptions {
  double relative_tolerance = 0.005;  // BRIEF §4: within 0.5 % of true depth
  double gradient_threshold = 0.05;   // g; ignored when dense
  bool dense = false;
  // Ground-truth foreground = true point inside V shrunk by this margin (m):
  // surfaces lying exactly on V's faces (the figurines table top is V's
  // bottom face, z = 0) are not foreground.
  double volume_margin = 0.001;
  void Check() const;
};

struct DepthMetrics {
  long long expected = 0;   // ground-truth foreground pixels that should get an estimate
  long long estimated = 0;  // of those, pixels with an estimate
  long long accurate = 0;   // of those, estimates within tolerance
  // (confidence, accurate) of every estimated pixel, for accuracy-coverage curves.
  std::vector<std::pair<float, bool>> samples;

  double Accuracy() const { return estimated ? static_cast<double>(accurate) / estimated : 0.0; }
  double Coverage() const { return expected ? static_cast<double>(estimated) / expected : 0.0; }
  void Add(const DepthMetrics& other);
};

struct CurvePoint {
  double min_confidence = 0;
  double accuracy = 0;
  double coverage = 0;
};

// `image` (CV_32FC3) gives ‖∇I‖ for the sparse criterion; may be empty when dense.
DepthMetrics EvaluateDepth(const DepthMap& estimate, const cv::Mat& true_depth, const cv::Mat& image,
                           const PinholeView& view, const BoundingBox& volume, const DepthMetricsOptions& options);

// Accuracy and coverage when only estimates with confidence >= threshold are
// kept, at `num_points` thresholds (quantiles of the confidences).
std::vector<CurvePoint> AccuracyCoverageCurve(const DepthMetrics& metrics, int num_points = 10);

}  // namespace lfrecon
