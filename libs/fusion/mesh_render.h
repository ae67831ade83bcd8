#pragma once
// A quick look at a mesh without a viewer: a turntable of shaded renders
// (vertex colours, or grey, lit from the camera) side by side in one image,
// written next to the mesh by `lfrecon run`.
#include <opencv2/core.hpp>

#include "geometry/pinhole_view.h"
#include "geometry/triangle_mesh.h"

namespace lfrecon {

struct TurntableOptions {
  int views = 4;             // azimuths evenly spread over 360°
  int tile_size = 320;       // pixels per square tile
  double elevation_deg = 30;  // camera height above V's centre, as an angle
  double hfov_deg = 40;
  void Check() const;  // throws OptionError
};

// Renders `mesh` from `options.views` cameras on a circle around `volume`'s
// centre (+z up), each framing V's bounding sphere; returns a CV_8UC3 BGR
// image of the tiles in one row (white where no surface is seen).
cv::Mat RenderTurntable(const TriangleMesh& mesh, const BoundingBox& volume, const TurntableOptions& options = {});

// One shaded render of `mesh` in `view` (CV_8UC3 BGR, white background).
cv::Mat RenderShaded(const TriangleMesh& mesh, const PinholeView& view);

}  // namespace lfrecon
