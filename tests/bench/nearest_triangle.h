#pragma once
// The nearest triangle of a mesh to a point and the point's distance to it,
// signed by that triangle's normal, for the benches' error reports (where
// the error lies, whether a surface is offset). Header-only: the benches are
// separate programs.
#include <Eigen/Core>
#include <Eigen/Geometry>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <limits>
#include <unordered_map>
#include <vector>

#include "geometry/triangle_mesh.h"

namespace lfrecon::bench {

// Nearest triangle within `reach` (hash grid); signed by the triangle's normal (+: outside).
class NearestTriangle {
 public:
  NearestTriangle(const TriangleMesh& m, double cell, int reach_cells) : m_(m), cell_(cell), reach_(reach_cells) {
    for (std::size_t t = 0; t < m.triangles.size(); ++t) {
      Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e9), hi = -lo;
      for (int k = 0; k < 3; ++k) {
        const Eigen::Vector3d v = m.vertices[m.triangles[t][k]].cast<double>();
        lo = lo.cwiseMin(v);
        hi = hi.cwiseMax(v);
      }
      const Eigen::Vector3i a = Cell(lo), b = Cell(hi);
      for (int i = a.x(); i <= b.x(); ++i)
        for (int j = a.y(); j <= b.y(); ++j)
          for (int k = a.z(); k <= b.z(); ++k) cells_[Key({i, j, k})].push_back(static_cast<int>(t));
    }
  }
  // Signed distance (+inf beyond reach) and the triangle's unit normal.
  double Signed(const Eigen::Vector3d& p, Eigen::Vector3d* normal = nullptr) const {
    const Eigen::Vector3i c = Cell(p);
    double best = std::numeric_limits<double>::infinity();
    Eigen::Vector3d bq = Eigen::Vector3d::Zero(), bn = Eigen::Vector3d::Zero();
    for (int r = 0; r <= reach_; ++r) {
      if (best <= (r - 1) * cell_) break;
      for (int i = -r; i <= r; ++i)
        for (int j = -r; j <= r; ++j)
          for (int k = -r; k <= r; ++k) {
            if (std::max({std::abs(i), std::abs(j), std::abs(k)}) != r) continue;
            const auto it = cells_.find(Key(c + Eigen::Vector3i(i, j, k)));
            if (it == cells_.end()) continue;
            for (int t : it->second) {
              const auto& tri = m_.triangles[t];
              const Eigen::Vector3d a = m_.vertices[tri[0]].cast<double>(), b = m_.vertices[tri[1]].cast<double>(),
                                    cc = m_.vertices[tri[2]].cast<double>();
              const Eigen::Vector3d q = ClosestPointOnTriangle(p, a, b, cc);
              const double d = (p - q).norm();
              if (d < best) {
                best = d;
                bq = q;
                bn = (b - a).cross(cc - a).normalized();
              }
            }
          }
    }
    if (normal) *normal = bn;
    if (!std::isfinite(best)) return best;
    return (p - bq).dot(bn) >= 0 ? best : -best;
  }

 private:
  Eigen::Vector3i Cell(const Eigen::Vector3d& p) const {
    return (p / cell_).array().floor().cast<int>();
  }
  static std::uint64_t Key(const Eigen::Vector3i& c) {
    const auto u = [](int v) { return static_cast<std::uint64_t>(v + (1 << 20)) & 0x1FFFFFull; };
    return u(c.x()) | (u(c.y()) << 21) | (u(c.z()) << 42);
  }
  const TriangleMesh& m_;
  double cell_;
  int reach_;
  std::unordered_map<std::uint64_t, std::vector<int>> cells_;
};

}  // namespace lfrecon::bench
