#pragma once
// NeRF-style transforms.json: each frame's `transform_matrix`
// is camera-to-world with OpenGL axes (x right, y up, z backward). Intrinsics
// are shared at the top level or given per frame: fl_x/fl_y (or
// camera_angle_x), cx, cy, w, h, and distortion k1, k2, p1, p2 when present
// (then the camera is OPENCV), or camera_model OPENCV_FISHEYE with k1..k4
// (Nerfstudio). Without w/h (Nerfstudio files may omit them) the size comes
// from `image_size` (e.g. the image file's header). A frame's mask_path
// (Nerfstudio) is kept as written. Poses are converted to cam_from_world with
// OpenCV axes on read and back on write.
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "geometry/camera.h"
#include "geometry/rigid3.h"

namespace lfrecon {

struct TransformsFrame {
  std::string file_path;  // as written in the file, e.g. "images/00000.jpg"
  Camera camera;
  Rigid3d cam_from_world;
  std::string mask_path;  // as written (Nerfstudio), empty when absent
};

// (width, height) of the image a frame's file_path names; nullopt: unknown.
using TransformsImageSize = std::function<std::optional<std::pair<int, int>>(const std::string& file_path)>;
std::vector<TransformsFrame> ReadTransformsJson(const std::filesystem::path& path,
                                                const TransformsImageSize& image_size = {});
// Writes shared intrinsics when every frame has the same camera, else per frame.
void WriteTransformsJson(const std::vector<TransformsFrame>& frames, const std::filesystem::path& path);

}  // namespace lfrecon
