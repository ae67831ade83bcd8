#pragma once
// Taubin's λ|μ smoothing of a triangle mesh (G. Taubin, "A signal processing
// approach to fair surface design", SIGGRAPH 1995): a shrinking Laplacian step
// (λ > 0) followed by an inflating one (μ < -λ), which damps the
// high-frequency noise of a surface without the shrinkage of plain Laplacian
// smoothing. Two bounds of ours keep it from eating what the mesh is for:
// each vertex stays within max_displacement of where it started, and
// components with fewer than min_component_vertices vertices (the fragments
// a thin part is often meshed as) are left as they are.
//
// Written here rather than taken from Open3D (TriangleMesh::FilterSmoothTaubin)
// for those two bounds: without them, on the figurines and the generated
// tabletops, thin recall@5mm fell by up to 0.017 (docs/benchmarks.md,
// "Open rims trimmed and the mesh smoothed").
#include <limits>

#include "geometry/triangle_mesh.h"

namespace lfrecon {

struct TaubinSmoothingOptions {
  int iterations = 6;  // λ|μ pairs; 0: no smoothing
  double lambda = 0.5;
  double mu = -0.53;  // Taubin's pass-band frequency k_PB = 1/λ + 1/μ ≈ 0.11 (Open3D's defaults)
  // Metres; no vertex moves farther than this from its input position.
  double max_displacement = std::numeric_limits<double>::infinity();
  int min_component_vertices = 100;

  void Check() const;  // throws OptionError
};

struct TaubinSmoothingStats {
  std::size_t vertices_moved = 0;   // vertices of components that were smoothed
  std::size_t vertices_capped = 0;  // of those, held at max_displacement at the end
  double mean_displacement = 0;     // metres, over the moved vertices
};

// Smooths `mesh` in place (uniform Laplacian over the 1-ring; boundary
// vertices are smoothed like the others, which pulls a ragged open rim in).
// Vertex normals are recomputed when the mesh had them; colours are kept.
TaubinSmoothingStats SmoothTaubin(TriangleMesh* mesh, const TaubinSmoothingOptions& options);

}  // namespace lfrecon
