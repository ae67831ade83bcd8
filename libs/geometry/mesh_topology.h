#pragma once
// Connectivity of a triangle mesh that mesh filters share: each vertex's
// 1-ring, connected components, open edges.
#include <cstddef>
#include <vector>

#include "geometry/triangle_mesh.h"

namespace lfrecon {

// The 1-ring of every vertex in CSR form: the neighbours of vertex i are
// neighbours[offsets[i] .. offsets[i + 1]), sorted, without repeats.
struct VertexAdjacency {
  std::vector<int> offsets, neighbours;
  int Degree(std::size_t i) const { return offsets[i + 1] - offsets[i]; }
};
VertexAdjacency BuildVertexAdjacency(const TriangleMesh& mesh);

// Per vertex: 1 when its connected component (vertices joined by triangle
// edges) has at least `min_vertices` vertices, else 0.
std::vector<char> VerticesOfLargeComponents(const VertexAdjacency& adjacency, int min_vertices);

// Per triangle, a bit per edge k (from vertex k to vertex k+1) that is open:
// no other triangle has it.
std::vector<unsigned char> OpenEdgeMasks(const TriangleMesh& mesh);

}  // namespace lfrecon
