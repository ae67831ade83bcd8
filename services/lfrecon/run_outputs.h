#pragma once
// `lfrecon run`'s outputs beside mesh.ply (issue 17): the mesh as OBJ/GLB, a
// point cloud, a COLMAP dense workspace, and report.html.
#include <CLI/CLI.hpp>
#include <filesystem>
#include <string>
#include <vector>

#include "geometry/pinhole_view.h"
#include "geometry/triangle_mesh.h"
#include "io/dataset.h"

namespace lfrecon::cli {

struct RunOutputFlags {
  std::string mesh_format = "ply";  // comma-separated: ply, obj, glb
  bool point_cloud = false;         // OUT/points.ply from the fused depth maps
  bool export_depth_colmap = false; // OUT/colmap/: a COLMAP dense workspace
  bool no_report_html = false;
  int previews = 4;                 // views with depth and edge previews (OUT/preview/, OUT/edges/)

  void AddTo(CLI::App* app);
  // The formats asked for, checked (OptionError naming --mesh-format).
  std::vector<std::string> MeshFormats() const;
  // The point cloud and the COLMAP workspace are made from the per-view depth maps.
  bool NeedsDepth() const { return point_cloud || export_depth_colmap; }
};

// After the pipeline wrote OUT/mesh.ply (and OUT/depth/STEM.pfm of `processed`
// views when NeedsDepth()): OUT/mesh.obj, mesh.glb, points.ply, colmap/, report.html.
void WriteRunOutputs(const RunOutputFlags& flags, const Dataset& ds, const std::vector<PinholeView>& views,
                     const std::vector<int>& processed, const TriangleMesh& mesh, double voxel_size,
                     const std::filesystem::path& out);

}  // namespace lfrecon::cli
