#include "geometry/view_graph.h"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <unordered_map>

#include "geometry/rigid3.h"

namespace lfrecon {
namespace {

void SortByAngle(const std::vector<Eigen::Vector3d>& dirs, int i, std::vector<int>* list) {
  std::vector<std::pair<double, int>> keyed;
  keyed.reserve(list->size());
  for (int j : *list) keyed.emplace_back(AngleBetweenDeg(dirs[i], dirs[j]), j);
  std::sort(keyed.begin(), keyed.end());
  for (size_t k = 0; k < keyed.size(); ++k) (*list)[k] = keyed[k].second;
}

}  // namespace

ViewGraph::ViewGraph(const std::vector<Eigen::Vector3d>& directions, double max_angle_deg, int max_index_gap)
    : max_angle_deg_(max_angle_deg) {
  directions_.reserve(directions.size());
  for (const auto& d : directions) directions_.push_back(d.normalized());
  const int n = static_cast<int>(directions_.size());
  neighbors_.assign(n, {});
  // Chord length of the angle; directions within the angle are within this
  // Euclidean distance, so they fall in the same or an adjacent cell.
  const double chord = 2.0 * std::sin(0.5 * std::min(max_angle_deg, 180.0) * M_PI / 180.0);
  const double cell = std::max(chord, 1e-6);
  auto key_of = [&](const Eigen::Vector3i& c) {
    return (static_cast<long long>(c.x()) * 73856093LL) ^ (static_cast<long long>(c.y()) * 19349663LL) ^
           (static_cast<long long>(c.z()) * 83492791LL);
  };
  auto cell_of = [&](const Eigen::Vector3d& d) {
    return Eigen::Vector3i(static_cast<int>(std::floor(d.x() / cell)), static_cast<int>(std::floor(d.y() / cell)),
                           static_cast<int>(std::floor(d.z() / cell)));
  };
  std::unordered_map<long long, std::vector<std::pair<Eigen::Vector3i, int>>> grid;
  std::vector<Eigen::Vector3i> cells(n);
  for (int i = 0; i < n; ++i) {
    cells[i] = cell_of(directions_[i]);
    grid[key_of(cells[i])].emplace_back(cells[i], i);
  }
  for (int i = 0; i < n; ++i) {
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const Eigen::Vector3i c = cells[i] + Eigen::Vector3i(dx, dy, dz);
          auto it = grid.find(key_of(c));
          if (it == grid.end()) continue;
          for (const auto& [cj, j] : it->second) {
            if (j == i || cj != c) continue;  // cj != c: hash collision
            if (max_index_gap > 0 && std::abs(j - i) > max_index_gap) continue;
            if (AngleBetweenDeg(directions_[i], directions_[j]) <= max_angle_deg) neighbors_[i].push_back(j);
          }
        }
    SortByAngle(directions_, i, &neighbors_[i]);
  }
}

double ViewGraph::AngleDeg(int i, int j) const { return AngleBetweenDeg(directions_.at(i), directions_.at(j)); }

std::vector<std::vector<int>> ViewGraph::BruteForce(const std::vector<Eigen::Vector3d>& directions,
                                                    double max_angle_deg) {
  std::vector<Eigen::Vector3d> dirs;
  for (const auto& d : directions) dirs.push_back(d.normalized());
  const int n = static_cast<int>(dirs.size());
  std::vector<std::vector<int>> out(n);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j)
      if (j != i && AngleBetweenDeg(dirs[i], dirs[j]) <= max_angle_deg) out[i].push_back(j);
    SortByAngle(dirs, i, &out[i]);
  }
  return out;
}

std::vector<char> SpacedAtLeast(const std::vector<Eigen::Vector3d>& directions, double min_step_deg) {
  std::vector<char> kept(directions.size(), 1);
  if (!(min_step_deg > 0) || directions.empty()) return kept;
  Eigen::Vector3d last = directions[0];
  for (std::size_t k = 1; k < directions.size(); ++k) {
    kept[k] = AtLeastStepDeg(AngleBetweenDeg(directions[k], last), min_step_deg);
    if (kept[k]) last = directions[k];
  }
  return kept;
}

bool AtLeastStepDeg(double angle_deg, double step_deg) { return angle_deg >= step_deg - 1e-6; }

std::vector<Eigen::Vector3d> ViewingDirections(const std::vector<PinholeView>& views) {
  std::vector<Eigen::Vector3d> dirs;
  dirs.reserve(views.size());
  for (const PinholeView& v : views) dirs.push_back(v.ViewingDirection());
  return dirs;
}

}  // namespace lfrecon
