#include "eval/mesh_metrics.h"

#include <Eigen/Geometry>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_reduce.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "util/error.h"

namespace lfrecon {
namespace {

std::uint64_t SplitMix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}
double ToUnit(std::uint64_t x) { return static_cast<double>(x >> 11) * (1.0 / 9007199254740992.0); }

// Closest point on triangle abc to p (Ericson, Real-Time Collision Detection §5.1.5); returns squared distance.
double PointTriangleDistance2(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                              const Eigen::Vector3d& c) {
  return (p - ClosestPointOnTriangle(p, a, b, c)).squaredNorm();
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  const std::size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  return v[mid];
}

}  // namespace

void ObservationOptions::Check() const {
  LFRECON_CHECK_OPTION(support_px >= 1 && support_px <= 15);
  LFRECON_CHECK_OPTION(std::isfinite(tolerance) && tolerance >= 0);
  LFRECON_CHECK_OPTION(std::isfinite(relative_tolerance) && relative_tolerance >= 0);
}

ObservationMask::ObservationMask(const std::vector<Eigen::Vector3d>* points, const ObservationOptions& options)
    : points_(points), options_(options), observed_(points->size(), 0) {
  options_.Check();
}

void ObservationMask::Add(const PinholeView& view, const cv::Mat& depth) {
  if (depth.empty() || depth.channels() != 1 || (depth.depth() != CV_32F && depth.depth() != CV_64F))
    throw std::invalid_argument("observation mask: the depth map must be one float channel");
  if (depth.cols != view.width || depth.rows != view.height)
    throw std::invalid_argument("observation mask: the depth map is " + std::to_string(depth.cols) + "x" +
                                std::to_string(depth.rows) + " but its view is " + std::to_string(view.width) +
                                "x" + std::to_string(view.height));
  cv::Mat d32;
  if (depth.depth() == CV_32F)
    d32 = depth;
  else
    depth.convertTo(d32, CV_32F);
  const cv::Mat d = d32;
  const int n = options_.support_px;
  const double half = 0.5 * (n - 1);
  const double tol = options_.tolerance, rel = options_.relative_tolerance;
  const std::vector<Eigen::Vector3d>& pts = *points_;
  const std::size_t added = tbb::parallel_reduce(
      tbb::blocked_range<std::size_t>(0, pts.size(), 1024), std::size_t{0},
      [&](const tbb::blocked_range<std::size_t>& r, std::size_t count) {
        for (std::size_t i = r.begin(); i < r.end(); ++i) {
          if (observed_[i]) continue;
          Eigen::Vector2d px;
          const double z = view.Project(pts[i], &px);
          if (!(z > 0) || !view.InImage(px)) continue;
          // The n x n pixel centres (c + 0.5, r + 0.5) nearest to px.
          const int c0 = std::max(0, static_cast<int>(std::floor(px.x() - half)));
          const int r0 = std::max(0, static_cast<int>(std::floor(px.y() - half)));
          const int c1 = std::min(d.cols, static_cast<int>(std::floor(px.x() - half)) + n);
          const int r1 = std::min(d.rows, static_cast<int>(std::floor(px.y() - half)) + n);
          double dmax = -std::numeric_limits<double>::infinity();
          for (int y = r0; y < r1 && dmax < std::numeric_limits<double>::infinity(); ++y) {
            const float* row = d.ptr<float>(y);
            for (int x = c0; x < c1; ++x) {
              const float v = row[x];
              if (!(v > 0) || !std::isfinite(v)) {  // no surface there: nothing occludes
                dmax = std::numeric_limits<double>::infinity();
                break;
              }
              dmax = std::max(dmax, static_cast<double>(v));
            }
          }
          if (z <= dmax + std::max(tol, rel * z)) {
            observed_[i] = 1;
            ++count;
          }
        }
        return count;
      },
      [](std::size_t a, std::size_t b) { return a + b; });
  num_observed_ += added;
  ++num_views_;
}

std::vector<std::uint8_t> ObservedMask(const std::vector<Eigen::Vector3d>& points, const GroundTruthViews& gt,
                                       const ObservationOptions& options) {
  ObservationMask mask(&points, options);
  for (int k = 0; k < static_cast<int>(gt.views.size()); ++k) {
    if (mask.NumObserved() == points.size()) break;  // nothing left to see
    const cv::Mat depth = gt.load(k);
    mask.Add(gt.views[static_cast<std::size_t>(k)], depth);
  }
  return mask.observed();
}

void MeshMetricsOptions::Check() const {
  if (thresholds.empty()) throw OptionError("mesh metrics: at least one threshold is needed");
  for (double t : thresholds) LFRECON_CHECK_OPTION(std::isfinite(t) && t > 0);
  LFRECON_CHECK_OPTION(std::isfinite(sample_spacing) && sample_spacing > 0);
  if (volume && !volume->IsValid()) throw OptionError("mesh metrics: the volume V must be a non-empty box");
  observation.Check();
}

const ThresholdScore* MeshMetrics::Find(double threshold) const {
  for (const ThresholdScore& s : scores)
    if (std::abs(s.threshold - threshold) <= 1e-9 * std::max(1.0, threshold)) return &s;
  return nullptr;
}

std::vector<Eigen::Vector3d> SampleSurface(const TriangleMesh& mesh, double spacing, std::uint64_t seed) {
  std::vector<Eigen::Vector3d> out;
  const double density = 1.0 / (spacing * spacing);
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const Eigen::Vector3i& tri = mesh.triangles[t];
    const Eigen::Vector3d a = mesh.vertices[tri[0]].cast<double>(), b = mesh.vertices[tri[1]].cast<double>(),
                          c = mesh.vertices[tri[2]].cast<double>();
    const double area = 0.5 * (b - a).cross(c - a).norm();
    if (!(area > 0)) continue;
    std::uint64_t h = SplitMix(seed ^ SplitMix(static_cast<std::uint64_t>(t)));
    const double expected = area * density;
    // Stochastic rounding keeps the expected count proportional to the area.
    const int n = static_cast<int>(std::floor(expected + ToUnit(h)));
    for (int k = 0; k < n; ++k) {
      h = SplitMix(h);
      const double r1 = std::sqrt(ToUnit(h));
      h = SplitMix(h);
      const double r2 = ToUnit(h);
      out.push_back((1 - r1) * a + r1 * (1 - r2) * b + r1 * r2 * c);
    }
  }
  return out;
}

SurfaceDistance::SurfaceDistance(const TriangleMesh& mesh, double max_distance, const BoundingBox* centroid_filter)
    : cell_(max_distance) {
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>(), b = mesh.vertices[t[1]].cast<double>(),
                          c = mesh.vertices[t[2]].cast<double>();
    if (centroid_filter && !centroid_filter->Contains((a + b + c) / 3.0)) continue;
    const int id = static_cast<int>(a_.size());
    a_.push_back(a);
    b_.push_back(b);
    c_.push_back(c);
    const Eigen::Vector3d lo = a.cwiseMin(b).cwiseMin(c) / cell_, hi = a.cwiseMax(b).cwiseMax(c) / cell_;
    for (int i = static_cast<int>(std::floor(lo.x())); i <= static_cast<int>(std::floor(hi.x())); ++i)
      for (int j = static_cast<int>(std::floor(lo.y())); j <= static_cast<int>(std::floor(hi.y())); ++j)
        for (int k = static_cast<int>(std::floor(lo.z())); k <= static_cast<int>(std::floor(hi.z())); ++k)
          cells_[Key(i, j, k)].push_back(id);
  }
}

std::uint64_t SurfaceDistance::Key(int i, int j, int k) const {
  const auto u = [](int v) { return static_cast<std::uint64_t>(static_cast<std::uint32_t>(v + (1 << 20))) & 0x1fffff; };
  return (u(i) << 42) | (u(j) << 21) | u(k);
}

double SurfaceDistance::Distance(const Eigen::Vector3d& p) const {
  const Eigen::Vector3d g = p / cell_;
  const int ci = static_cast<int>(std::floor(g.x())), cj = static_cast<int>(std::floor(g.y())),
            ck = static_cast<int>(std::floor(g.z()));
  // The 27 cells around p, nearest first; a cell farther than the best distance so far is skipped.
  std::array<std::pair<double, int>, 27> order;
  for (int n = 0; n < 27; ++n) {
    const int d[3] = {n % 3 - 1, (n / 3) % 3 - 1, n / 9 - 1};
    const int c[3] = {ci + d[0], cj + d[1], ck + d[2]};
    double box2 = 0;
    for (int a = 0; a < 3; ++a) {
      const double lo = c[a] * cell_, hi = lo + cell_;
      const double e = std::max({lo - p[a], 0.0, p[a] - hi});
      box2 += e * e;
    }
    order[n] = {box2, n};
  }
  std::sort(order.begin(), order.end());
  double best = cell_ * cell_;
  bool found = false;
  for (const auto& [box2, n] : order) {
    if (box2 > best) break;
    const auto it = cells_.find(Key(ci + n % 3 - 1, cj + (n / 3) % 3 - 1, ck + n / 9 - 1));
    if (it == cells_.end()) continue;
    for (int id : it->second) {
      const double d2 = PointTriangleDistance2(p, a_[id], b_[id], c_[id]);
      if (d2 <= best) {
        best = d2;
        found = true;
      }
    }
  }
  return found ? std::sqrt(best) : std::numeric_limits<double>::infinity();
}

std::vector<double> SurfaceDistance::Distances(const std::vector<Eigen::Vector3d>& points) const {
  std::vector<double> d(points.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, points.size(), 256), [&](const auto& r) {
    for (std::size_t i = r.begin(); i < r.end(); ++i) d[i] = Distance(points[i]);
  });
  return d;
}

MeshMetrics EvaluateMesh(const TriangleMesh& predicted, const TriangleMesh& ground_truth,
                         const TriangleMesh* ground_truth_thin, const MeshMetricsOptions& options,
                         const GroundTruthViews* views) {
  options.Check();
  const double max_t = *std::max_element(options.thresholds.begin(), options.thresholds.end());
  const BoundingBox* volume = options.volume ? &*options.volume : nullptr;
  MeshMetrics m;
  m.predicted_area = predicted.SurfaceArea();
  m.gt_area = ground_truth.SurfaceArea();

  std::vector<Eigen::Vector3d> pred = SampleSurface(predicted, options.sample_spacing, options.seed);
  if (volume) {
    const std::size_t total = pred.size();
    pred.erase(std::remove_if(pred.begin(), pred.end(), [&](const Eigen::Vector3d& p) { return !volume->Contains(p); }),
               pred.end());
    m.predicted_samples_outside = total - pred.size();
  }
  const std::vector<Eigen::Vector3d> gt = SampleSurface(ground_truth, options.sample_spacing, options.seed + 1);
  std::vector<Eigen::Vector3d> thin;
  if (ground_truth_thin) thin = SampleSurface(*ground_truth_thin, options.sample_spacing, options.seed + 2);
  m.predicted_samples = pred.size();
  m.gt_samples = gt.size();
  m.thin_samples = thin.size();
  // Observation masks of the ground-truth and thin samples, in one pass over the depth maps.
  std::vector<std::uint8_t> gt_seen, thin_seen;
  if (views) {
    std::vector<Eigen::Vector3d> all;
    all.reserve(gt.size() + thin.size());
    all.insert(all.end(), gt.begin(), gt.end());
    all.insert(all.end(), thin.begin(), thin.end());
    ObservationMask mask(&all, options.observation);
    for (int k = 0; k < static_cast<int>(views->views.size()); ++k) {
      if (mask.NumObserved() == all.size()) break;
      mask.Add(views->views[static_cast<std::size_t>(k)], views->load(k));
    }
    const std::vector<std::uint8_t>& seen = mask.observed();
    gt_seen.assign(seen.begin(), seen.begin() + static_cast<std::ptrdiff_t>(gt.size()));
    thin_seen.assign(seen.begin() + static_cast<std::ptrdiff_t>(gt.size()), seen.end());
    m.has_observation = true;
    m.observation_views = static_cast<int>(views->views.size());
    m.gt_observed_samples = static_cast<std::size_t>(std::count(gt_seen.begin(), gt_seen.end(), 1));
    m.thin_observed_samples = static_cast<std::size_t>(std::count(thin_seen.begin(), thin_seen.end(), 1));
  }

  const SurfaceDistance to_gt(ground_truth, max_t);
  const SurfaceDistance to_pred(predicted, max_t, volume);
  const std::vector<double> acc = to_gt.Distances(pred);
  const std::vector<double> comp = to_pred.Distances(gt);
  const std::vector<double> thin_comp = to_pred.Distances(thin);
  auto share = [](const std::vector<double>& d, double t) {
    if (d.empty()) return 0.0;
    return static_cast<double>(std::count_if(d.begin(), d.end(), [t](double x) { return x <= t; })) / d.size();
  };
  auto masked_share = [](const std::vector<double>& d, const std::vector<std::uint8_t>& seen, double t) {
    std::size_t n = 0, in = 0;
    for (std::size_t i = 0; i < d.size(); ++i)
      if (seen[i]) {
        ++n;
        in += d[i] <= t;
      }
    return n ? static_cast<double>(in) / n : 0.0;
  };
  auto f = [](double p, double r) { return p + r > 0 ? 2 * p * r / (p + r) : 0.0; };
  for (double t : options.thresholds) {
    ThresholdScore s;
    s.threshold = t;
    s.precision = share(acc, t);
    s.recall = share(comp, t);
    s.fscore = f(s.precision, s.recall);
    if (ground_truth_thin) s.thin_recall = share(thin_comp, t);
    if (views) {
      s.recall_observed = masked_share(comp, gt_seen, t);
      s.fscore_observed = f(s.precision, s.recall_observed);
      if (ground_truth_thin) s.thin_recall_observed = masked_share(thin_comp, thin_seen, t);
    }
    m.scores.push_back(s);
  }
  auto capped = [max_t](std::vector<double> d) {
    for (double& x : d) x = std::min(x, max_t);
    return d;
  };
  m.median_accuracy = Median(capped(acc));
  m.median_completeness = Median(capped(comp));
  if (views) {
    std::vector<double> seen_comp;
    seen_comp.reserve(m.gt_observed_samples);
    for (std::size_t i = 0; i < comp.size(); ++i)
      if (gt_seen[i]) seen_comp.push_back(comp[i]);
    m.median_completeness_observed = Median(capped(std::move(seen_comp)));
  }
  return m;
}

}  // namespace lfrecon
