#pragma once
// Mesh quality against ground truth (BRIEF §4, in the manner of Tanks and
// Temples): both surfaces are sampled uniformly by area (deterministic seed);
// precision at τ = share of reconstructed samples within τ of the ground-truth
// surface, recall at τ = share of ground-truth samples within τ of the
// reconstruction, F = 2PR / (P + R). Distances are point-to-surface (to the
// nearest triangle), not point-to-sample, so the sampling density of the
// target does not bias them. Reconstructed samples outside V are dropped
// (precision only judges V), and recall measures the distance to the
// reconstruction's triangles whose centroid lies in V. Thin recall is recall
// of the thin-only ground truth (gt_thin.ply).
//
// Observation masks (BRIEF §4, like DTU's): only ground truth that some camera
// sees counts. A ground-truth sample is observed when some ground-truth depth
// map sees it unoccluded (ObservedMask); recall, F and thin recall are then
// reported twice, over all ground-truth samples and over the observed ones.
#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <opencv2/core.hpp>
#include <optional>
#include <unordered_map>
#include <vector>

#include "geometry/pinhole_view.h"
#include "geometry/triangle_mesh.h"

namespace lfrecon {

// When a ground-truth depth map D of a view sees a world point X: X projects
// inside the image (COLMAP pixel convention, upper-left centre (0.5, 0.5)) at
// planar depth z > 0, and
//     z <= max{ D(c) : c among the support_px x support_px pixel centres nearest
//               to the projection } + max(tolerance, relative_tolerance * z).
// Why the maximum over a small support, not D at the nearest pixel: where the
// depth is linear across the support (any plane, also at grazing angles) the
// largest of the pixel centres that surround the projection is never below the
// depth at the projection itself, so no visible point is lost to the sampling;
// at silhouettes and on parts thinner than a pixel (wires), the support
// reaches the background behind them and the point counts as seen. 2 x 2 (the
// four centres around the projection, the bilinear support) is the smallest
// support with that property; 3 x 3 around the nearest pixel is more lenient.
// The price of either is a band at most ~1 pixel wide of truly hidden surface
// next to an occluding contour (e.g. a bottom face standing on a table, seen
// at grazing angle just under the base's edge) counted as observed.
// The tolerance absorbs what the support does not: curvature within the
// support, a ground-truth mesh tessellated apart from the depth renderer, and
// pose error of datasets whose poses are perturbed against the renderer's
// (figurines-noisy: ~0.5 mm, 0.02 deg per frame). It is kept small because any
// tolerance also counts hidden surface within it behind an occluder as seen.
// Depth 0 or non-finite (no surface) never occludes.
// Figurines (60 depth maps, 640x360): the bases' bottom faces standing on the
// table (27.9 % of gt_mesh.ply's area, hidden from every view) come out 2.0 %
// observed at these defaults, 1.4 % with the nearest pixel alone, 2.7 % at
// 3 x 3, 6.1 % at 3 x 3 with max(3 mm, 1 %); the rest of gt_mesh.ply 94.8 %
// (94.1, 95.4, 97.2 %); gt_mesh.ply as a whole 68.9 %, gt_thin.ply 98.8 %.
struct ObservationOptions {
  int support_px = 2;                   // N: the N x N pixel centres nearest to the projection (1: the nearest)
  double tolerance = 0.002;             // m
  double relative_tolerance = 0.0025;   // of the point's planar depth
  void Check() const;                   // throws OptionError
};

// Accumulates the observation mask of a fixed set of points one depth map at
// a time (so only one map need be in memory); parallel over the points.
class ObservationMask {
 public:
  ObservationMask(const std::vector<Eigen::Vector3d>* points, const ObservationOptions& options);
  // `depth`: planar depth in metres (CV_32F or CV_64F, one channel), view-sized
  // (throws std::invalid_argument otherwise).
  void Add(const PinholeView& view, const cv::Mat& depth);
  const std::vector<std::uint8_t>& observed() const { return observed_; }  // 1 = observed
  std::size_t NumObserved() const { return num_observed_; }
  int NumViews() const { return num_views_; }

 private:
  const std::vector<Eigen::Vector3d>* points_;
  ObservationOptions options_;
  std::vector<std::uint8_t> observed_;
  std::size_t num_observed_ = 0;
  int num_views_ = 0;
};

// Ground-truth depth maps: views[k] with its depth map load(k) (called once
// per k, in order; the map is released before the next is loaded).
struct GroundTruthViews {
  std::vector<PinholeView> views;
  std::function<cv::Mat(int k)> load;
};

// 1 for each point some depth map of `gt` sees (ObservationOptions).
std::vector<std::uint8_t> ObservedMask(const std::vector<Eigen::Vector3d>& points, const GroundTruthViews& gt,
                                       const ObservationOptions& options);

struct MeshMetricsOptions {
  std::vector<double> thresholds = {0.002, 0.005, 0.010};  // τ in metres (BRIEF §4: 2, 5, 10 mm)
  double sample_spacing = 0.001;  // one sample per spacing² of area (1 mm: 10^6 samples per m²)
  std::uint64_t seed = 1;
  std::optional<BoundingBox> volume;  // V; unset: no restriction
  ObservationOptions observation;     // used when EvaluateMesh is given ground-truth views
  void Check() const;                 // throws OptionError
};

struct ThresholdScore {
  double threshold = 0;
  double precision = 0;
  double recall = 0;
  double fscore = 0;
  double thin_recall = -1;  // -1 when no thin ground truth was given
  // The same over the observed ground-truth samples only; -1 without ground-truth views.
  double recall_observed = -1;
  double fscore_observed = -1;
  double thin_recall_observed = -1;  // -1 also when no thin ground truth was given
};

struct MeshMetrics {
  std::vector<ThresholdScore> scores;  // one per threshold, in the options' order
  std::size_t predicted_samples = 0;   // reconstructed samples inside V (the precision denominator)
  std::size_t predicted_samples_outside = 0;
  std::size_t gt_samples = 0;
  std::size_t thin_samples = 0;
  bool has_observation = false;          // ground-truth views were given
  int observation_views = 0;             // depth maps used for the mask
  std::size_t gt_observed_samples = 0;   // ground-truth samples some depth map sees
  std::size_t thin_observed_samples = 0;
  double ObservedShare() const { return gt_samples ? static_cast<double>(gt_observed_samples) / gt_samples : 0.0; }
  double ThinObservedShare() const {
    return thin_samples ? static_cast<double>(thin_observed_samples) / thin_samples : 0.0;
  }
  double predicted_area = 0;  // m², whole reconstructed mesh
  double gt_area = 0;
  // Median distance of reconstructed samples to the ground truth and back,
  // capped at the largest threshold (metres).
  double median_accuracy = 0;
  double median_completeness = 0;
  double median_completeness_observed = -1;  // over the observed ground truth; -1 without views
  const ThresholdScore* Find(double threshold) const;
};

// Area-uniform random points on the mesh, about area / spacing² of them;
// the same (mesh, spacing, seed) always give the same points.
std::vector<Eigen::Vector3d> SampleSurface(const TriangleMesh& mesh, double spacing, std::uint64_t seed);

// Distance from points to a triangle soup, up to `max_distance` (beyond it:
// +infinity), with a uniform hash grid of cell size max_distance.
class SurfaceDistance {
 public:
  SurfaceDistance(const TriangleMesh& mesh, double max_distance, const BoundingBox* centroid_filter = nullptr);
  double Distance(const Eigen::Vector3d& p) const;
  std::vector<double> Distances(const std::vector<Eigen::Vector3d>& points) const;  // parallel

 private:
  std::uint64_t Key(int i, int j, int k) const;
  double cell_;
  std::vector<Eigen::Vector3d> a_, b_, c_;
  std::unordered_map<std::uint64_t, std::vector<int>> cells_;
};

// With `views`, also the observed figures (ThresholdScore::*_observed): the
// ground-truth and thin samples are masked in one pass over the depth maps.
MeshMetrics EvaluateMesh(const TriangleMesh& predicted, const TriangleMesh& ground_truth,
                         const TriangleMesh* ground_truth_thin, const MeshMetricsOptions& options,
                         const GroundTruthViews* views = nullptr);

}  // namespace lfrecon
