#pragma once
// PLY meshes and point clouds. Reads ASCII and binary little-endian files
// (float or double coordinates, optional normals nx/ny/nz, colours
// red/green/blue as uchar, faces as a list of vertex indices; polygons are
// fanned into triangles). Writes binary little-endian.
#include <filesystem>

#include "geometry/triangle_mesh.h"

namespace lfrecon {

TriangleMesh ReadPly(const std::filesystem::path& path);
// A mesh with no triangles is written as a point cloud (no face element).
void WritePly(const TriangleMesh& mesh, const std::filesystem::path& path);

}  // namespace lfrecon
