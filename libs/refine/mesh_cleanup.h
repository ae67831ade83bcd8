#pragma once
// Clean-up of a reconstructed mesh: dropping small connected components
// (floaters: bits of surface that a few views' spurious depths left in free
// space, disconnected from the object).
#include <cstddef>

#include "geometry/triangle_mesh.h"

namespace lfrecon {

struct ComponentFilterStats {
  std::size_t components = 0, components_removed = 0;
  std::size_t triangles_removed = 0;
  double area_removed = 0;  // m²
};

// The mesh without its connected components (triangles sharing vertices)
// whose area is below `min_area` (m²). Vertex attributes are kept; unused
// vertices are dropped. min_area <= 0 returns the mesh as it is.
TriangleMesh RemoveSmallComponents(const TriangleMesh& mesh, double min_area, ComponentFilterStats* stats = nullptr);

}  // namespace lfrecon
