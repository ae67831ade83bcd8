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
#include <Eigen/Core>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <unordered_map>
#include <vector>

#include "geometry/triangle_mesh.h"

namespace lfrecon {

struct MeshMetricsOptions {
  std::vector<double> thresholds = {0.002, 0.005, 0.010};  // τ in metres (BRIEF §4: 2, 5, 10 mm)
  double sample_spacing = 0.001;  // one sample per spacing² of area (1 mm: 10^6 samples per m²)
  std::uint64_t seed = 1;
  std::optional<BoundingBox> volume;  // V; unset: no restriction
  void Check() const;                 // throws OptionError
};

struct ThresholdScore {
  double threshold = 0;
  double precision = 0;
  double recall = 0;
  double fscore = 0;
  double thin_recall = -1;  // -1 when no thin ground truth was given
};

struct MeshMetrics {
  std::vector<ThresholdScore> scores;  // one per threshold, in the options' order
  std::size_t predicted_samples = 0;   // reconstructed samples inside V (the precision denominator)
  std::size_t predicted_samples_outside = 0;
  std::size_t gt_samples = 0;
  std::size_t thin_samples = 0;
  double predicted_area = 0;  // m², whole reconstructed mesh
  double gt_area = 0;
  // Median distance of reconstructed samples to the ground truth and back,
  // capped at the largest threshold (metres).
  double median_accuracy = 0;
  double median_completeness = 0;
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

MeshMetrics EvaluateMesh(const TriangleMesh& predicted, const TriangleMesh& ground_truth,
                         const TriangleMesh* ground_truth_thin, const MeshMetricsOptions& options);

}  // namespace lfrecon
