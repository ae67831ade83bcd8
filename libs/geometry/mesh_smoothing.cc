#include "geometry/mesh_smoothing.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "util/error.h"

namespace lfrecon {

void TaubinSmoothingOptions::Check() const {
  LFRECON_CHECK_OPTION(iterations >= 0);
  LFRECON_CHECK_OPTION(lambda > 0 && lambda < 1);
  LFRECON_CHECK_OPTION(mu < -lambda && mu > -1);
  LFRECON_CHECK_OPTION(max_displacement > 0);
  LFRECON_CHECK_OPTION(min_component_vertices >= 0);
}

namespace {

// The 1-ring of every vertex in CSR form (sorted, without repeats).
struct Adjacency {
  std::vector<int> offsets, neighbours;
};

Adjacency BuildAdjacency(const TriangleMesh& mesh) {
  const std::size_t n = mesh.vertices.size();
  std::vector<int> degree(n + 1, 0);
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) degree[t[k]] += 2;
  Adjacency adj;
  adj.offsets.assign(n + 1, 0);
  for (std::size_t i = 0; i < n; ++i) adj.offsets[i + 1] = adj.offsets[i] + degree[i];
  adj.neighbours.resize(adj.offsets[n]);
  std::vector<int> fill(adj.offsets.begin(), adj.offsets.end() - 1);
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      adj.neighbours[fill[t[k]]++] = t[(k + 1) % 3];
      adj.neighbours[fill[t[k]]++] = t[(k + 2) % 3];
    }
  // Sort and drop repeats per vertex, then compact.
  int write = 0;
  for (std::size_t i = 0; i < n; ++i) {
    auto first = adj.neighbours.begin() + adj.offsets[i], last = adj.neighbours.begin() + adj.offsets[i + 1];
    std::sort(first, last);
    const int count = static_cast<int>(std::unique(first, last) - first);
    std::copy(first, first + count, adj.neighbours.begin() + write);
    adj.offsets[i] = write;
    write += count;
  }
  adj.offsets[n] = write;
  adj.neighbours.resize(write);
  return adj;
}

// Whether each vertex belongs to a component of at least `min_vertices` vertices.
std::vector<char> InLargeComponent(const Adjacency& adj, std::size_t n, int min_vertices) {
  std::vector<char> large(n, 0);
  std::vector<char> seen(n, 0);
  std::vector<int> stack, members;
  for (std::size_t s = 0; s < n; ++s) {
    if (seen[s]) continue;
    members.clear();
    seen[s] = 1;
    stack.push_back(static_cast<int>(s));
    while (!stack.empty()) {
      const int v = stack.back();
      stack.pop_back();
      members.push_back(v);
      for (int e = adj.offsets[v]; e < adj.offsets[v + 1]; ++e)
        if (!seen[adj.neighbours[e]]) seen[adj.neighbours[e]] = 1, stack.push_back(adj.neighbours[e]);
    }
    if (static_cast<int>(members.size()) >= min_vertices)
      for (int v : members) large[v] = 1;
  }
  return large;
}

}  // namespace

TaubinSmoothingStats SmoothTaubin(TriangleMesh* mesh, const TaubinSmoothingOptions& options) {
  options.Check();
  TaubinSmoothingStats stats;
  const std::size_t n = mesh->vertices.size();
  if (options.iterations == 0 || n == 0 || mesh->triangles.empty()) return stats;
  const Adjacency adj = BuildAdjacency(*mesh);
  std::vector<char> moves = InLargeComponent(adj, n, options.min_component_vertices);
  for (std::size_t i = 0; i < n; ++i)
    if (adj.offsets[i] == adj.offsets[i + 1]) moves[i] = 0;  // unreferenced vertex

  const std::vector<Eigen::Vector3f> input = mesh->vertices;
  std::vector<Eigen::Vector3f> next(n);
  const float max_d = static_cast<float>(std::min<double>(options.max_displacement, 1e30));
  auto step = [&](float factor) {
    const auto& cur = mesh->vertices;
    for (std::size_t i = 0; i < n; ++i) {
      if (!moves[i]) {
        next[i] = cur[i];
        continue;
      }
      Eigen::Vector3f mean = Eigen::Vector3f::Zero();
      for (int e = adj.offsets[i]; e < adj.offsets[i + 1]; ++e) mean += cur[adj.neighbours[e]];
      mean /= static_cast<float>(adj.offsets[i + 1] - adj.offsets[i]);
      Eigen::Vector3f p = cur[i] + factor * (mean - cur[i]);
      const Eigen::Vector3f d = p - input[i];
      const float len = d.norm();
      if (len > max_d) p = input[i] + d * (max_d / len);
      next[i] = p;
    }
    mesh->vertices.swap(next);
  };
  for (int it = 0; it < options.iterations; ++it) {
    step(static_cast<float>(options.lambda));
    step(static_cast<float>(options.mu));
  }

  double sum = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (!moves[i]) continue;
    const float d = (mesh->vertices[i] - input[i]).norm();
    ++stats.vertices_moved;
    sum += d;
    if (d >= max_d * 0.999f) ++stats.vertices_capped;
  }
  stats.mean_displacement = stats.vertices_moved ? sum / stats.vertices_moved : 0;
  if (mesh->HasNormals()) mesh->ComputeVertexNormals();
  return stats;
}

}  // namespace lfrecon
