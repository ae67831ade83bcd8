#include "refine/voxel_carving.h"

#include <spdlog/spdlog.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <opencv2/imgproc.hpp>

#include <algorithm>
#include <cmath>
#include <deque>
#include <stdexcept>
#include <unordered_map>
#include <unordered_set>

#include "util/error.h"
#include "util/progress.h"

namespace lfrecon {
namespace {

std::uint64_t Key(const Eigen::Vector3i& v) {
  const auto u = [](int x) { return static_cast<std::uint64_t>(x + (1 << 20)) & 0x1FFFFFull; };
  return u(v.x()) | (u(v.y()) << 21) | (u(v.z()) << 42);
}

// Bilinear BGR of a CV_32FC3 image at COLMAP pixel coordinates (u, v).
Eigen::Vector3d SampleBgr(const cv::Mat& image, double u, double v) {
  const double x = u - 0.5, y = v - 0.5;
  const int c0 = static_cast<int>(std::floor(x)), r0 = static_cast<int>(std::floor(y));
  const double fx = x - c0, fy = y - r0;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (int k = 0; k < 4; ++k) {
    const int r = std::clamp(r0 + (k >> 1), 0, image.rows - 1), c = std::clamp(c0 + (k & 1), 0, image.cols - 1);
    const double w = ((k & 1) ? fx : 1 - fx) * ((k >> 1) ? fy : 1 - fy);
    const cv::Vec3f q = image.at<cv::Vec3f>(r, c);
    sum += w * Eigen::Vector3d(q[0], q[1], q[2]);
  }
  return sum;
}

// Mean vertex normal of the mesh around each occupied voxel: every vertex
// lies in the cell of 8 voxel centres around it and adds its normal to the
// occupied ones. This is how the mesh normals reach the voxels of R (the
// exposed voxels of each round touch the current mesh).
std::unordered_map<std::uint64_t, Eigen::Vector3d> VoxelNormals(const VoxelGrid& grid, const TriangleMesh& mesh) {
  std::unordered_map<std::uint64_t, Eigen::Vector3d> normals;
  const double s = grid.voxel_size();
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) {
    const Eigen::Vector3d g = (mesh.vertices[i].cast<double>() - grid.volume().min) / s - Eigen::Vector3d::Constant(0.5);
    const Eigen::Vector3i base(static_cast<int>(std::floor(g.x())), static_cast<int>(std::floor(g.y())),
                               static_cast<int>(std::floor(g.z())));
    for (int k = 0; k < 8; ++k) {
      const Eigen::Vector3i v = base + Eigen::Vector3i(k & 1, (k >> 1) & 1, (k >> 2) & 1);
      if (grid.State(v) != VoxelState::kOccupied) continue;
      auto [it, inserted] = normals.emplace(Key(v), Eigen::Vector3d::Zero());
      it->second += mesh.normals[i].cast<double>();
    }
  }
  for (auto& [k, n] : normals) {
    const double len = n.norm();
    n = len > 1e-12 ? Eigen::Vector3d(n / len) : Eigen::Vector3d::Zero();
  }
  return normals;
}

bool BordersUnknown(const VoxelGrid& grid, const Eigen::Vector3i& v) {
  for (const Eigen::Vector3i& d : kSixNeighbours)
    if (grid.State(v + d) == VoxelState::kUnknown) return true;
  return false;
}

// Where no mesh vertex reached an exposed voxel: the mean direction to its free neighbours.
Eigen::Vector3d FallbackNormal(const VoxelGrid& grid, const Eigen::Vector3i& v) {
  Eigen::Vector3d n = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3i& d : kSixNeighbours)
    if (grid.State(v + d) == VoxelState::kFree) n += d.cast<double>();
  const double len = n.norm();
  return len > 1e-12 ? Eigen::Vector3d(n / len) : Eigen::Vector3d::Zero();
}

}  // namespace

void CarvingOptions::Check() const {
  LFRECON_CHECK_OPTION(region_depth >= 1);
  LFRECON_CHECK_OPTION(max_rounds >= 0);
  LFRECON_CHECK_OPTION(consistency_threshold > 0 && consistency_threshold <= 1);
  LFRECON_CHECK_OPTION(min_views >= 1);
  LFRECON_CHECK_OPTION(std::isfinite(visibility_tolerance) && visibility_tolerance >= 0);
  LFRECON_CHECK_OPTION(std::isfinite(mask_margin_px) && mask_margin_px >= 0);
}

std::size_t CarvingResult::TotalCarved() const {
  std::size_t n = carved_outside_masks;
  for (const CarvingRound& r : rounds) n += r.carved;
  return n;
}

cv::Mat RenderBackFaceDepth(const TriangleMesh& mesh, const PinholeView& view) {
  cv::Mat depth(view.height, view.width, CV_32F, cv::Scalar(0));
  std::vector<Eigen::Vector3d> cam(mesh.vertices.size());
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) cam[i] = view.R * mesh.vertices[i].cast<double>() + view.t;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    const Eigen::Vector3d &a = cam[t[0]], &b = cam[t[1]], &c = cam[t[2]];
    if (a.z() <= 1e-6 || b.z() <= 1e-6 || c.z() <= 1e-6) continue;
    // Back-facing: the outward normal points away from the camera (at the origin here).
    if ((b - a).cross(c - a).dot(a) <= 0) continue;
    Eigen::Vector3d z, u, v;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d& x = cam[t[k]];
      const Eigen::Vector3d h = view.K * x;
      z[k] = x.z();
      u[k] = h.x() / h.z();
      v[k] = h.y() / h.z();
    }
    const double area = (u[1] - u[0]) * (v[2] - v[0]) - (u[2] - u[0]) * (v[1] - v[0]);
    if (std::abs(area) < 1e-12) continue;
    const int c0 = std::max(0, static_cast<int>(std::ceil(u.minCoeff() - 0.5)));
    const int c1 = std::min(view.width - 1, static_cast<int>(std::floor(u.maxCoeff() - 0.5)));
    const int r0 = std::max(0, static_cast<int>(std::ceil(v.minCoeff() - 0.5)));
    const int r1 = std::min(view.height - 1, static_cast<int>(std::floor(v.maxCoeff() - 0.5)));
    for (int r = r0; r <= r1; ++r) {
      float* row = depth.ptr<float>(r);
      const double py = r + 0.5;
      for (int col = c0; col <= c1; ++col) {
        const double px = col + 0.5;
        const double b0 = ((u[1] - px) * (v[2] - py) - (u[2] - px) * (v[1] - py)) / area;
        const double b1 = ((u[2] - px) * (v[0] - py) - (u[0] - px) * (v[2] - py)) / area;
        const double b2 = 1 - b0 - b1;
        if (b0 < 0 || b1 < 0 || b2 < 0) continue;
        const double zz = 1.0 / (b0 / z[0] + b1 / z[1] + b2 / z[2]);  // perspective-correct
        if (row[col] == 0 || zz < row[col]) row[col] = static_cast<float>(zz);
      }
    }
  }
  return depth;
}

double PhotoConsistencyVariance(const Eigen::Vector3d& center, const Eigen::Vector3d& normal,
                                const std::vector<PinholeView>& views, const std::vector<cv::Mat>& images,
                                const std::vector<cv::Mat>& back_depths, double visibility_tolerance, int min_views,
                                int* views_used, double min_cos) {
  // Weighted mean and variance in one pass (West's weighted update).
  double wsum = 0;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  double m2 = 0;
  int used = 0;
  for (std::size_t i = 0; i < views.size(); ++i) {
    const PinholeView& view = views[i];
    const double w = normal.dot((view.Center() - center).normalized());  // eq. 15
    if (!(w > 0) || w < min_cos) continue;
    Eigen::Vector2d px;
    const double z = view.Project(center, &px);
    if (z <= 0 || !view.InImage(px)) continue;
    const float back = back_depths[i].at<float>(static_cast<int>(px.y()), static_cast<int>(px.x()));
    // Visible unless behind the first back face on its ray (§5); no back face
    // at its pixel: nothing of the mesh is on that ray, so nothing hides it.
    if (back > 0 && z > back + visibility_tolerance) continue;
    const Eigen::Vector3d c = SampleBgr(images[i], px.x(), px.y());
    ++used;
    wsum += w;
    const Eigen::Vector3d delta = c - mean;
    mean += (w / wsum) * delta;
    m2 += w * delta.dot(c - mean);
  }
  if (views_used) *views_used = used;
  if (used < min_views || wsum <= 0) return -1;
  return std::max(0.0, m2 / wsum);  // eq. 16
}

std::vector<Eigen::Vector3i> VoxelsOutsideMasks(const VoxelGrid& grid, const std::vector<PinholeView>& views,
                                                const std::vector<cv::Mat>& masks, double margin_px,
                                                std::size_t* mask_views) {
  if (!masks.empty() && masks.size() != views.size())
    throw std::invalid_argument("VoxelsOutsideMasks: " + std::to_string(masks.size()) + " masks for " +
                                std::to_string(views.size()) + " views");
  // Per view with a mask: each pixel's distance to the nearest object pixel.
  std::vector<std::size_t> used;
  std::vector<cv::Mat> distance(views.size());
  for (std::size_t i = 0; i < masks.size(); ++i) {
    const cv::Mat& m = masks[i];
    if (m.empty()) continue;
    if (m.type() != CV_8U || m.rows != views[i].height || m.cols != views[i].width)
      throw std::invalid_argument("VoxelsOutsideMasks: each mask must be CV_8U of its view's size");
    if (cv::countNonZero(m) == 0) continue;  // no object in it: more likely a wrong mask than an empty view
    cv::distanceTransform(m == 0, distance[i], cv::DIST_L2, cv::DIST_MASK_PRECISE);
    used.push_back(i);
  }
  if (mask_views) *mask_views = used.size();
  if (used.empty()) return {};
  const std::vector<Eigen::Vector3i> occupied = grid.OccupiedVoxels();
  const double half_diagonal = 0.5 * std::sqrt(3.0) * grid.voxel_size();
  std::vector<char> outside(occupied.size(), 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, occupied.size()), [&](const auto& range) {
    for (std::size_t k = range.begin(); k < range.end(); ++k) {
      const Eigen::Vector3d x = grid.Center(occupied[k]);
      for (std::size_t i : used) {
        const PinholeView& view = views[i];
        Eigen::Vector2d px;
        const double z = view.Project(x, &px);
        if (z <= 0 || !view.InImage(px)) continue;
        // The voxel's projected half-diagonal (a sphere around the cube, at
        // the centre's depth): the cube lies within it.
        const double radius_px = half_diagonal * std::max(view.K(0, 0), view.K(1, 1)) / z;
        const float d = distance[i].at<float>(static_cast<int>(px.y()), static_cast<int>(px.x()));
        if (d > margin_px + radius_px) {
          outside[k] = 1;
          break;
        }
      }
    }
  });
  std::vector<Eigen::Vector3i> out;
  for (std::size_t k = 0; k < occupied.size(); ++k)
    if (outside[k]) out.push_back(occupied[k]);
  return out;
}

CarvingResult VoxelCarving(VoxelGrid* grid, const std::vector<ColorView>& color_views, const CarvingOptions& options,
                           const std::vector<cv::Mat>& masks) {
  options.Check();
  if (!masks.empty() && masks.size() != color_views.size())
    throw std::invalid_argument("VoxelCarving: " + std::to_string(masks.size()) + " masks for " +
                                std::to_string(color_views.size()) + " views");
  std::vector<PinholeView> views;
  std::vector<cv::Mat> images;
  for (const ColorView& cv : color_views) {
    if (cv.image.rows != cv.view.height || cv.image.cols != cv.view.width ||
        (cv.image.type() != CV_32FC3 && cv.image.type() != CV_8UC3))
      throw std::invalid_argument("VoxelCarving: each image must be CV_32FC3 or CV_8UC3 of its view's size");
    views.push_back(cv.view);
    cv::Mat f;
    if (cv.image.type() == CV_8UC3)
      cv.image.convertTo(f, CV_32FC3, 1.0 / 255.0);
    else
      f = cv.image;
    images.push_back(f);
  }
  CarvingResult result;
  result.occupied_before = grid->CountOccupied();
  if (options.carve_outside_masks && !masks.empty()) {
    Timer timer;
    const std::vector<Eigen::Vector3i> outside =
        VoxelsOutsideMasks(*grid, views, masks, options.mask_margin_px, &result.mask_views);
    for (const Eigen::Vector3i& v : outside) grid->Carve(v);
    result.carved_outside_masks = outside.size();
    spdlog::info("carving: {} of {} occupied voxels outside the object masks of {} views carved ({:.1f} s)",
                 outside.size(), result.occupied_before, result.mask_views, timer.Seconds());
  }

  // R: occupied voxels within region_depth voxels (6-connected steps through
  // occupied voxels) of the outer surface; depth 1 = the exposed voxels.
  std::unordered_set<std::uint64_t> region;
  {
    std::deque<std::pair<Eigen::Vector3i, int>> queue;
    for (const Eigen::Vector3i& v : grid->OccupiedVoxels())
      if (grid->IsExposed(v)) {
        region.insert(Key(v));
        queue.emplace_back(v, 1);
      }
    while (!queue.empty()) {
      const auto [v, d] = queue.front();
      queue.pop_front();
      if (d >= options.region_depth) continue;
      for (const Eigen::Vector3i& o : kSixNeighbours) {
        const Eigen::Vector3i u = v + o;
        if (grid->State(u) == VoxelState::kOccupied && region.insert(Key(u)).second) queue.emplace_back(u, d + 1);
      }
    }
  }
  result.region_voxels = region.size();
  const double tolerance = options.visibility_tolerance * grid->voxel_size();

  for (int round = 0; round < options.max_rounds && !views.empty(); ++round) {
    Timer timer;
    CarvingRound stats;
    const TriangleMesh mesh = grid->ExtractMesh();
    if (mesh.triangles.empty()) break;
    std::vector<cv::Mat> back(views.size());
    tbb::parallel_for(std::size_t{0}, views.size(), [&](std::size_t i) { back[i] = RenderBackFaceDepth(mesh, views[i]); });
    const auto normals = VoxelNormals(*grid, mesh);

    std::vector<Eigen::Vector3i> candidates;
    for (const Eigen::Vector3i& v : grid->OccupiedVoxels())
      if (region.count(Key(v)) && grid->IsExposed(v) && !(options.keep_inner_wall && BordersUnknown(*grid, v)))
        candidates.push_back(v);
    // 1 carve, 0 keep, -1 unseen, 2 keep: inconsistent, and as inconsistent deeper
    std::vector<signed char> verdict(candidates.size(), 0);
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, candidates.size()), [&](const auto& range) {
      for (std::size_t k = range.begin(); k < range.end(); ++k) {
        const Eigen::Vector3i& v = candidates[k];
        const auto it = normals.find(Key(v));
        Eigen::Vector3d n = it != normals.end() ? it->second : Eigen::Vector3d::Zero();
        if (n.squaredNorm() < 0.5) n = FallbackNormal(*grid, v);
        const Eigen::Vector3d x = options.sample_at_surface ? SurfacePoint(*grid, v) : grid->Center(v);
        const double pc = PhotoConsistencyVariance(x, n, views, images, back, tolerance,
                                                   options.min_views, nullptr, options.min_cos);
        verdict[k] = pc < 0 ? -1 : (1.0 - pc < options.consistency_threshold ? 1 : 0);
        if (verdict[k] == 1 && options.require_consistent_behind) {
          // Deeper, a voxel at a time through R's depth: carve when a point looks consistent or free space
          // follows (a thin part or a sheet seen through); keep when every point seen looks inconsistent, up
          // to R's depth or to the unobserved inside.
          const Eigen::Vector3d step = grid->voxel_size() * n.normalized();
          bool inconsistent_behind = false, resolved = false;
          for (int s = 1; s <= options.region_depth && !resolved; ++s) {
            const Eigen::Vector3d behind = x - s * step;
            const VoxelState state = grid->State(grid->Index(behind));
            if (state != VoxelState::kOccupied) {
              resolved = state == VoxelState::kFree;
              break;
            }
            const double pc_behind = PhotoConsistencyVariance(behind, n, views, images, back, tolerance,
                                                              options.min_views, nullptr, options.min_cos);
            if (pc_behind < 0) continue;
            if (1.0 - pc_behind >= options.consistency_threshold) resolved = true;
            else inconsistent_behind = true;
          }
          if (!resolved && inconsistent_behind) verdict[k] = 2;
        }
      }
    });
    for (std::size_t k = 0; k < candidates.size(); ++k) {
      if (verdict[k] < 0) {
        ++stats.unseen;
        continue;
      }
      ++stats.judged;
      if (verdict[k] == 2) ++stats.kept_inconsistent_behind;
      if (verdict[k] == 1) {
        grid->Carve(candidates[k]);
        ++stats.carved;
      }
    }
    stats.seconds = timer.Seconds();
    spdlog::info("carving round {}: {} exposed voxels of R judged ({} seen by fewer than {} views), {} carved, {} "
                 "inconsistent kept (as inconsistent deeper) ({:.1f} s)",
                 round + 1, stats.judged, stats.unseen, options.min_views, stats.carved,
                 stats.kept_inconsistent_behind, stats.seconds);
    result.rounds.push_back(stats);
    if (stats.carved == 0) break;
  }
  result.occupied_after = grid->CountOccupied();
  return result;
}

Eigen::Vector3d SurfacePoint(const VoxelGrid& grid, const Eigen::Vector3i& v) {
  const Eigen::Vector3d c = grid.Center(v);
  const float iso = static_cast<float>(grid.threshold());
  const float hv = grid.Value(v);
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  int crossings = 0;
  for (const Eigen::Vector3i& d : kSixNeighbours) {
    const Eigen::Vector3i u = v + d;
    if (grid.State(u) != VoxelState::kFree) continue;
    const float hu = grid.Value(u);
    const double t = hv > hu ? std::clamp(static_cast<double>((hv - iso) / (hv - hu)), 0.0, 1.0) : 0.5;
    p += c + t * grid.voxel_size() * d.cast<double>();
    ++crossings;
  }
  return crossings > 0 ? Eigen::Vector3d(p / crossings) : c;
}

OrientedPoints BoundaryPoints(const VoxelGrid& grid) {
  const TriangleMesh mesh = grid.ExtractMesh();
  const auto normals = VoxelNormals(grid, mesh);
  OrientedPoints out;
  for (const Eigen::Vector3i& v : grid.OccupiedVoxels()) {
    if (!grid.IsExposed(v)) continue;
    const auto it = normals.find(Key(v));
    Eigen::Vector3d n = it != normals.end() ? it->second : Eigen::Vector3d::Zero();
    if (n.squaredNorm() < 0.5) n = FallbackNormal(grid, v);
    if (n.squaredNorm() < 0.5) continue;
    out.points.push_back(SurfacePoint(grid, v));
    out.normals.push_back(n);
  }
  return out;
}

}  // namespace lfrecon
