#include "geometry/mesh_topology.h"

#include <algorithm>
#include <cstdint>
#include <utility>

namespace lfrecon {

VertexAdjacency BuildVertexAdjacency(const TriangleMesh& mesh) {
  const std::size_t n = mesh.vertices.size();
  VertexAdjacency adj;
  adj.offsets.assign(n + 1, 0);
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) adj.offsets[t[k] + 1] += 2;
  for (std::size_t i = 0; i < n; ++i) adj.offsets[i + 1] += adj.offsets[i];
  adj.neighbours.resize(adj.offsets[n]);
  std::vector<int> fill(adj.offsets.begin(), adj.offsets.end() - 1);
  for (const auto& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) {
      adj.neighbours[fill[t[k]]++] = t[(k + 1) % 3];
      adj.neighbours[fill[t[k]]++] = t[(k + 2) % 3];
    }
  // Sort and drop repeats per vertex, compacting in place.
  int write = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const auto first = adj.neighbours.begin() + adj.offsets[i], last = adj.neighbours.begin() + adj.offsets[i + 1];
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

std::vector<char> VerticesOfLargeComponents(const VertexAdjacency& adj, int min_vertices) {
  const std::size_t n = adj.offsets.size() - 1;
  std::vector<char> large(n, 0), seen(n, 0);
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

std::vector<unsigned char> OpenEdgeMasks(const TriangleMesh& mesh) {
  // Every directed half-edge as (min, max, triangle * 3 + k), sorted: an edge is open when its key appears once.
  struct HalfEdge {
    std::uint64_t key;
    std::uint32_t slot;
  };
  std::vector<HalfEdge> half(mesh.triangles.size() * 3);
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t a = mesh.triangles[t][k], b = mesh.triangles[t][(k + 1) % 3];
      half[t * 3 + k] = {(std::uint64_t{std::min(a, b)} << 32) | std::max(a, b), static_cast<std::uint32_t>(t * 3 + k)};
    }
  std::sort(half.begin(), half.end(), [](const HalfEdge& x, const HalfEdge& y) { return x.key < y.key; });
  std::vector<unsigned char> open(mesh.triangles.size(), 0);
  for (std::size_t i = 0; i < half.size();) {
    std::size_t j = i + 1;
    while (j < half.size() && half[j].key == half[i].key) ++j;
    if (j - i == 1) open[half[i].slot / 3] |= static_cast<unsigned char>(1u << (half[i].slot % 3));
    i = j;
  }
  return open;
}

}  // namespace lfrecon
