#pragma once
// Trimming the open rims of a reconstructed surface. A fused iso-surface ends
// where the observed band of the grid ends: at silhouettes, at holes, at the
// edge of what the views saw. The triangles on such a rim (with an edge no
// other triangle shares) come from grid cells at the end of the evidence and
// lie off the true surface more often than the rest: on the figurines'
// carved mesh, the triangles touching a rim vertex have 35 % of their area
// within 2 mm of the truth against 76 % for the whole mesh
// (docs/benchmarks.md, "Open rims trimmed and the mesh smoothed").
#include <cstddef>

#include "geometry/triangle_mesh.h"

namespace lfrecon {

struct RimTrimOptions {
  // Rounds; each drops every triangle with an open edge (so a rim recedes by
  // about one triangle per round). 0: nothing is trimmed.
  int rounds = 1;
  // Components with fewer vertices are left whole: a thin part is often meshed
  // as a small open fragment that is all rim.
  int min_component_vertices = 100;

  void Check() const;  // throws OptionError
};

struct RimTrimStats {
  std::size_t triangles_removed = 0;
  double area_removed = 0;  // m²
};

// Trims `mesh` in place; vertices no triangle uses any more are dropped
// (normals and colours follow their vertices; normals are recomputed).
RimTrimStats TrimOpenRims(TriangleMesh* mesh, const RimTrimOptions& options);

}  // namespace lfrecon
