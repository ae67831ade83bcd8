#pragma once
// Connected components of 3-D points for the benches' cluster reports: two
// points belong together when their cells on a grid of `cell` metres are
// equal or 26-neighbours. Header-only: the benches are separate programs.
#include <Eigen/Core>

#include <cmath>
#include <cstdint>
#include <unordered_map>
#include <vector>

namespace lfrecon::bench {

// One label per point, 0 .. *count - 1 (numbered in the order their first point appears).
inline std::vector<int> GridComponents(const std::vector<Eigen::Vector3d>& pts, double cell, int* count) {
  const auto key = [](const Eigen::Vector3i& c) {
    const auto u = [](int v) { return static_cast<std::uint64_t>(v + (1 << 20)) & 0x1FFFFFull; };
    return u(c.x()) | (u(c.y()) << 21) | (u(c.z()) << 42);
  };
  const auto cell_of = [&](const Eigen::Vector3d& p) -> Eigen::Vector3i {
    return (p / cell).array().floor().cast<int>();
  };
  std::unordered_map<std::uint64_t, std::vector<int>> grid;
  for (std::size_t i = 0; i < pts.size(); ++i) grid[key(cell_of(pts[i]))].push_back(static_cast<int>(i));
  std::vector<int> label(pts.size(), -1);
  int next = 0;
  for (std::size_t s = 0; s < pts.size(); ++s) {
    if (label[s] >= 0) continue;
    const Eigen::Vector3i c0 = cell_of(pts[s]);
    for (int i : grid.at(key(c0))) label[i] = next;
    std::vector<Eigen::Vector3i> stack = {c0};
    while (!stack.empty()) {
      const Eigen::Vector3i c = stack.back();
      stack.pop_back();
      for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dz = -1; dz <= 1; ++dz) {
            const Eigen::Vector3i n = c + Eigen::Vector3i(dx, dy, dz);
            const auto it = grid.find(key(n));
            if (it == grid.end() || label[it->second[0]] >= 0) continue;
            for (int i : it->second) label[i] = next;
            stack.push_back(n);
          }
    }
    ++next;
  }
  *count = next;
  return label;
}

}  // namespace lfrecon::bench
