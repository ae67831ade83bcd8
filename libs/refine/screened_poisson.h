#pragma once
// Screened Poisson surface reconstruction (Kazhdan & Hoppe 2013) of oriented
// points, by Open3D's wrapper of Kazhdan's PoissonRecon. Open3D's headers are
// included only by screened_poisson.cc (they are slow to compile).
#include <optional>

#include "geometry/triangle_mesh.h"
#include "refine/refine_options.h"
#include "refine/voxel_carving.h"

namespace lfrecon {

struct PoissonStats {
  std::size_t points = 0;
  int depth = 0;  // octree depth used
  std::size_t vertices_raw = 0, triangles_raw = 0;  // before trimming
  std::size_t trimmed_density = 0, trimmed_distance = 0, trimmed_volume = 0;  // vertices removed by each rule
  double seconds = 0;
};

// The watertight Poisson surface of `points`, then trimmed: vertices below
// the density quantile, farther than options.max_point_distance voxels from
// every point, or outside `volume` (when given) are removed with their
// triangles. `voxel_size` sets the automatic depth and the distance unit.
// Outward normals per vertex; no colours. Throws OptionError and
// std::invalid_argument (points and normals of different sizes).
TriangleMesh ScreenedPoissonSurface(const OrientedPoints& points, double voxel_size, const PoissonOptions& options,
                                    const std::optional<BoundingBox>& volume = std::nullopt,
                                    PoissonStats* stats = nullptr);

}  // namespace lfrecon
