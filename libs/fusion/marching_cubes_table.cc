#include "fusion/marching_cubes_table.h"

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <stdexcept>
#include <string>

namespace lfrecon::mc {
namespace {

Eigen::Vector3d CornerPos(int k) { return Eigen::Vector3d(k & 1, (k >> 1) & 1, (k >> 2) & 1); }

std::array<Edge, 12> MakeEdges() {
  std::array<Edge, 12> edges;
  int e = 0;
  for (int axis = 0; axis < 3; ++axis)
    for (int k = 0; k < 8; ++k)
      if (!((k >> axis) & 1)) edges[e++] = Edge{k, k | (1 << axis), axis};
  return edges;
}

int EdgeIndex(const std::array<Edge, 12>& edges, int a, int b) {
  for (int e = 0; e < 12; ++e)
    if ((edges[e].corner0 == a && edges[e].corner1 == b) || (edges[e].corner0 == b && edges[e].corner1 == a)) return e;
  throw std::logic_error("marching cubes: corners share no edge");
}

// Two crossing points whose edges share a cube face: a triangle edge between
// them (unless it is one of the loop's own segments) would lie in that face,
// where the neighbouring cell may put one too (non-manifold, flat webs).
bool ShareFace(const Edge& a, const Edge& b) {
  for (int axis = 0; axis < 3; ++axis) {
    if (a.axis == axis || b.axis == axis) continue;
    const int sa = (a.corner0 >> axis) & 1, sb = (b.corner0 >> axis) & 1;
    if (sa == sb) return true;
  }
  return false;
}

// Triangulates a loop (polygon of edge indices) choosing, by dynamic
// programming over all triangulations, the fewest diagonals that lie in a
// cube face, then the shortest total diagonal length.
void Triangulate(const std::vector<int>& loop, const std::array<Edge, 12>& edges,
                 std::vector<std::array<int, 3>>* tris) {
  const int n = static_cast<int>(loop.size());
  auto mid = [&](int e) -> Eigen::Vector3d {
    return 0.5 * (CornerPos(edges[e].corner0) + CornerPos(edges[e].corner1));
  };
  auto diag_cost = [&](int i, int j) {
    if (j - i == 1 || (i == 0 && j == n - 1)) return 0.0;  // a loop segment
    return (ShareFace(edges[loop[i]], edges[loop[j]]) ? 100.0 : 0.0) + (mid(loop[i]) - mid(loop[j])).norm();
  };
  std::vector<std::vector<double>> cost(n, std::vector<double>(n, 0.0));
  std::vector<std::vector<int>> split(n, std::vector<int>(n, -1));
  for (int len = 2; len < n; ++len) {
    for (int i = 0; i + len < n; ++i) {
      const int j = i + len;
      cost[i][j] = 1e18;
      for (int k = i + 1; k < j; ++k) {
        const double c = cost[i][k] + cost[k][j] + diag_cost(i, k) + diag_cost(k, j);
        if (c < cost[i][j]) {
          cost[i][j] = c;
          split[i][j] = k;
        }
      }
    }
  }
  std::vector<std::pair<int, int>> stack = {{0, n - 1}};
  while (!stack.empty()) {
    const auto [i, j] = stack.back();
    stack.pop_back();
    if (j - i < 2) continue;
    const int k = split[i][j];
    tris->push_back({loop[i], loop[k], loop[j]});
    stack.push_back({i, k});
    stack.push_back({k, j});
  }
}

std::vector<std::array<int, 3>> MakeCase(int mask, const std::array<Edge, 12>& edges) {
  auto inside = [mask](int k) { return ((mask >> k) & 1) != 0; };
  auto mid = [&](int e) -> Eigen::Vector3d { return 0.5 * (CornerPos(edges[e].corner0) + CornerPos(edges[e].corner1)); };
  std::array<int, 12> next;
  next.fill(-1);
  for (int a = 0; a < 3; ++a) {
    const int b = (a + 1) % 3, c = (a + 2) % 3;
    for (int s = 0; s < 2; ++s) {
      int q[4];
      const int bc[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
      for (int k = 0; k < 4; ++k) q[k] = (s << a) | (bc[k][0] << b) | (bc[k][1] << c);
      int fe[4];
      bool cross[4];
      int ncross = 0;
      for (int k = 0; k < 4; ++k) {
        fe[k] = EdgeIndex(edges, q[k], q[(k + 1) % 4]);
        cross[k] = inside(q[k]) != inside(q[(k + 1) % 4]);
        ncross += cross[k];
      }
      if (ncross == 0) continue;
      std::vector<std::array<int, 2>> segments;
      if (ncross == 2) {
        std::array<int, 2> seg{-1, -1};
        int n = 0;
        for (int k = 0; k < 4; ++k)
          if (cross[k]) seg[n++] = fe[k];
        segments.push_back(seg);
      } else {  // ambiguous face: cut off each outside corner, the inside corners stay joined
        for (int k = 0; k < 4; ++k)
          if (!inside(q[k])) segments.push_back({fe[(k + 3) % 4], fe[k]});
      }
      int inside_corner = -1;
      for (int k = 0; k < 4; ++k)
        if (inside(q[k])) inside_corner = q[k];
      Eigen::Vector3d normal = Eigen::Vector3d::Zero();
      normal[a] = s ? 1.0 : -1.0;
      const Eigen::Vector3d I = CornerPos(inside_corner);
      for (auto seg : segments) {
        const Eigen::Vector3d A = mid(seg[0]), B = mid(seg[1]);
        if ((B - A).cross(I - A).dot(normal) < 0) std::swap(seg[0], seg[1]);
        if (next[seg[0]] != -1) throw std::logic_error("marching cubes: edge used twice (mask " + std::to_string(mask) + ", face " + std::to_string(a) + "/" + std::to_string(s) + ", edge " + std::to_string(seg[0]) + ")");
        next[seg[0]] = seg[1];
      }
    }
  }
  std::vector<std::array<int, 3>> tris;
  std::array<bool, 12> used{};
  for (int e = 0; e < 12; ++e) {
    if (next[e] == -1 || used[e]) continue;
    std::vector<int> loop;
    for (int cur = e; !used[cur]; cur = next[cur]) {
      if (next[cur] == -1) throw std::logic_error("marching cubes: open loop");
      used[cur] = true;
      loop.push_back(cur);
    }
    Triangulate(loop, edges, &tris);
  }
  return tris;
}

struct Tables {
  std::array<Edge, 12> edges;
  std::array<std::vector<std::array<int, 3>>, 256> cases;
  Tables() : edges(MakeEdges()) {
    for (int m = 0; m < 256; ++m) cases[m] = MakeCase(m, edges);
    // Orientation: with only corner 0 inside the normal must point away from it.
    const auto& t = cases[1].at(0);
    auto mid = [&](int e) -> Eigen::Vector3d { return 0.5 * (CornerPos(edges[e].corner0) + CornerPos(edges[e].corner1)); };
    const Eigen::Vector3d n = (mid(t[1]) - mid(t[0])).cross(mid(t[2]) - mid(t[0]));
    if (n.dot(Eigen::Vector3d(1, 1, 1)) < 0)
      for (auto& c : cases)
        for (auto& tri : c) std::swap(tri[1], tri[2]);
  }
};

const Tables& GetTables() {
  static const Tables tables;
  return tables;
}

}  // namespace

const std::array<Edge, 12>& Edges() { return GetTables().edges; }

const std::vector<std::array<int, 3>>& Triangles(int inside_mask) { return GetTables().cases.at(inside_mask & 255); }

}  // namespace lfrecon::mc
