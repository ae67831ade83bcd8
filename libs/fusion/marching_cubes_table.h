#pragma once
// Marching-cubes case tables, generated (not typed in) from the cube's faces:
// on each face the edges with a sign change are joined into segments (on an
// ambiguous face the two inside corners stay connected, which keeps thin
// diagonal features in one piece; the rule depends only on the face, so
// neighbouring cells agree and the surface is watertight), the segments are
// chained into loops and each loop is fanned into triangles.
#include <array>
#include <vector>

namespace lfrecon::mc {

// Corner k of a cell sits at offset (k & 1, (k >> 1) & 1, (k >> 2) & 1).
struct Edge {
  int corner0 = 0;  // the corner with the smaller coordinate along `axis`
  int corner1 = 0;
  int axis = 0;
};
const std::array<Edge, 12>& Edges();

// Triangles (triples of edge indices) for an inside mask (bit k set: corner k
// is inside, i.e. its value >= the iso-value), wound so that the right-hand
// normal points from inside to outside.
const std::vector<std::array<int, 3>>& Triangles(int inside_mask);

}  // namespace lfrecon::mc
