#pragma once
// NeRF-style transforms.json: each frame's `transform_matrix`
// is camera-to-world with OpenGL axes (x right, y up, z backward). Intrinsics
// are shared at the top level or given per frame: fl_x/fl_y (or
// camera_angle_x), cx, cy, w, h, and distortion k1, k2, p1, p2 when present
// (then the camera is OPENCV). Poses are converted to cam_from_world with
// OpenCV axes on read and back on write.
#include <filesystem>
#include <string>
#include <vector>

#include "geometry/camera.h"
#include "geometry/rigid3.h"

namespace lfrecon {

struct TransformsFrame {
  std::string file_path;  // as written in the file, e.g. "images/00000.jpg"
  Camera camera;
  Rigid3d cam_from_world;
};

std::vector<TransformsFrame> ReadTransformsJson(const std::filesystem::path& path);
// Writes shared intrinsics when every frame has the same camera, else per frame.
void WriteTransformsJson(const std::vector<TransformsFrame>& frames, const std::filesystem::path& path);

}  // namespace lfrecon
