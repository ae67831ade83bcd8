#include "refine/screened_poisson.h"

// The only file that sees Open3D.
#include <open3d/geometry/PointCloud.h>
#include <open3d/geometry/TriangleMesh.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <unordered_map>
#include <vector>

#include "util/error.h"
#include "util/progress.h"

namespace lfrecon {

void PoissonOptions::Check() const {
  LFRECON_CHECK_OPTION(depth >= 0 && depth <= 14);
  LFRECON_CHECK_OPTION(std::isfinite(scale) && scale >= 1);
  LFRECON_CHECK_OPTION(density_quantile >= 0 && density_quantile < 1);
  LFRECON_CHECK_OPTION(std::isfinite(max_point_distance));
  LFRECON_CHECK_OPTION(threads == -1 || threads >= 1);
}

namespace {

// Points bucketed by cells of the trimming distance: "is any point within r?"
class PointHash {
 public:
  PointHash(const std::vector<Eigen::Vector3d>& points, double r) : r_(r) {
    for (std::size_t i = 0; i < points.size(); ++i) cells_[Key(Cell(points[i]))].push_back(points[i]);
  }
  bool AnyWithin(const Eigen::Vector3d& p) const {
    const Eigen::Vector3i c = Cell(p);
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto it = cells_.find(Key(c + Eigen::Vector3i(dx, dy, dz)));
          if (it == cells_.end()) continue;
          for (const Eigen::Vector3d& q : it->second)
            if ((q - p).squaredNorm() <= r_ * r_) return true;
        }
    return false;
  }

 private:
  Eigen::Vector3i Cell(const Eigen::Vector3d& p) const {
    return {static_cast<int>(std::floor(p.x() / r_)), static_cast<int>(std::floor(p.y() / r_)),
            static_cast<int>(std::floor(p.z() / r_))};
  }
  static std::uint64_t Key(const Eigen::Vector3i& c) {
    const auto u = [](int v) { return static_cast<std::uint64_t>(v + (1 << 20)) & 0x1FFFFFull; };
    return u(c.x()) | (u(c.y()) << 21) | (u(c.z()) << 42);
  }
  double r_;
  std::unordered_map<std::uint64_t, std::vector<Eigen::Vector3d>> cells_;
};

}  // namespace

TriangleMesh ScreenedPoissonSurface(const OrientedPoints& input, double voxel_size, const PoissonOptions& options,
                                    const std::optional<BoundingBox>& volume, PoissonStats* stats_out) {
  options.Check();
  if (!(voxel_size > 0)) throw OptionError("poisson: voxel_size must be > 0");
  if (input.points.size() != input.normals.size())
    throw std::invalid_argument("ScreenedPoissonSurface: points and normals differ in number");
  Timer timer;
  PoissonStats stats;
  stats.points = input.points.size();
  TriangleMesh out;
  // PoissonRecon needs a few points to build an octree at all.
  if (input.points.size() < 16) {
    if (stats_out) *stats_out = stats;
    return out;
  }
  open3d::geometry::PointCloud cloud;
  cloud.points_ = input.points;
  cloud.normals_ = input.normals;
  Eigen::Vector3d lo = cloud.GetMinBound(), hi = cloud.GetMaxBound();
  int depth = options.depth;
  if (depth == 0) {
    const double cube = options.scale * (hi - lo).maxCoeff();
    depth = std::clamp(static_cast<int>(std::ceil(std::log2(std::max(1.0, cube / voxel_size)))), 1, 12);
  }
  stats.depth = depth;
  auto [mesh, densities] = open3d::geometry::TriangleMesh::CreateFromPointCloudPoisson(
      cloud, static_cast<std::size_t>(depth), 0.0f, static_cast<float>(options.scale), options.linear_fit,
      options.threads);
  stats.vertices_raw = mesh->vertices_.size();
  stats.triangles_raw = mesh->triangles_.size();

  const std::size_t nv = mesh->vertices_.size();
  std::vector<char> keep(nv, 1);
  if (options.density_quantile > 0 && !densities.empty()) {
    std::vector<double> sorted = densities;
    const std::size_t q = static_cast<std::size_t>(options.density_quantile * (sorted.size() - 1));
    std::nth_element(sorted.begin(), sorted.begin() + q, sorted.end());
    const double cut = sorted[q];
    for (std::size_t i = 0; i < nv; ++i)
      if (densities[i] < cut) keep[i] = 0, ++stats.trimmed_density;
  }
  if (options.max_point_distance > 0) {
    const PointHash hash(input.points, options.max_point_distance * voxel_size);
    for (std::size_t i = 0; i < nv; ++i)
      if (keep[i] && !hash.AnyWithin(mesh->vertices_[i])) keep[i] = 0, ++stats.trimmed_distance;
  }
  if (volume) {
    for (std::size_t i = 0; i < nv; ++i)
      if (keep[i] && !volume->Contains(mesh->vertices_[i])) keep[i] = 0, ++stats.trimmed_volume;
  }
  std::vector<int> index(nv, -1);
  for (std::size_t i = 0; i < nv; ++i) {
    if (!keep[i]) continue;
    index[i] = static_cast<int>(out.vertices.size());
    out.vertices.push_back(mesh->vertices_[i].cast<float>());
  }
  for (const Eigen::Vector3i& t : mesh->triangles_) {
    const Eigen::Vector3i m(index[t[0]], index[t[1]], index[t[2]]);
    if (m.minCoeff() >= 0) out.triangles.push_back(m);
  }
  // Drop vertices no triangle uses any more.
  std::vector<int> used(out.vertices.size(), -1);
  TriangleMesh compact;
  for (Eigen::Vector3i t : out.triangles) {
    for (int k = 0; k < 3; ++k) {
      if (used[t[k]] < 0) {
        used[t[k]] = static_cast<int>(compact.vertices.size());
        compact.vertices.push_back(out.vertices[t[k]]);
      }
      t[k] = used[t[k]];
    }
    compact.triangles.push_back(t);
  }
  compact.ComputeVertexNormals();
  stats.seconds = timer.Seconds();
  spdlog::info("poisson: {} points, depth {}, {} -> {} triangles (trimmed vertices: {} density, {} distance, {} "
               "outside V) in {:.1f} s",
               stats.points, stats.depth, stats.triangles_raw, compact.triangles.size(), stats.trimmed_density,
               stats.trimmed_distance, stats.trimmed_volume, stats.seconds);
  if (stats_out) *stats_out = stats;
  return compact;
}

}  // namespace lfrecon
