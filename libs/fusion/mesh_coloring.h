#pragma once
// Vertex colours for a reconstructed mesh from a few frames: each vertex takes
// the cosine-weighted mean colour of the views that see it (facing the camera
// and not hidden behind the view's depth).
#include <opencv2/core.hpp>
#include <vector>

#include "geometry/pinhole_view.h"
#include "geometry/triangle_mesh.h"

namespace lfrecon {

struct ColorView {
  PinholeView view;
  cv::Mat image;  // CV_32FC3 BGR in [0, 1] or CV_8UC3 BGR, the view's size
  // Optional planar depth (CV_32F, 0 = none) for the visibility test; empty:
  // the mesh's own depth is rendered (RenderMeshDepth).
  cv::Mat depth;
};

struct ColoringOptions {
  double depth_tolerance = 0.004;  // metres a vertex may lie behind the visible depth
  double min_cos = 0.1;            // views seeing the surface more obliquely are skipped
  void Check() const;              // throws OptionError
};

// Sets mesh->colors (RGB; grey where no view sees a vertex). Computes vertex
// normals first if the mesh has none.
void ColorizeMesh(TriangleMesh* mesh, const std::vector<ColorView>& views, const ColoringOptions& options = {});

// Z-buffer of the mesh in `view`: the nearest planar depth at each pixel
// centre (CV_32F, 0 where no triangle covers it). Triangles crossing the
// camera plane are skipped.
cv::Mat RenderMeshDepth(const TriangleMesh& mesh, const PinholeView& view);

}  // namespace lfrecon
