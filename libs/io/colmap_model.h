#pragma once
// COLMAP sparse models: cameras, images (poses) and, optionally, points3D,
// in COLMAP's text (cameras.txt, images.txt, points3D.txt) and binary
// (cameras.bin, images.bin, points3D.bin) formats. Poses are cam_from_world
// (world -> camera, OpenCV axes), quaternions in COLMAP's QW QX QY QZ order.
// Readers throw InputError naming the file and the field/line that is wrong.
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "geometry/camera.h"
#include "geometry/rigid3.h"

namespace lfrecon {

struct ColmapImage {
  std::uint32_t image_id = 0;
  std::uint32_t camera_id = 0;
  std::string name;  // relative to the image folder
  Rigid3d cam_from_world;
};

struct ColmapModel {
  std::map<std::uint32_t, Camera> cameras;
  std::vector<ColmapImage> images;  // sorted by name
  std::size_t num_points3D = 0;     // points are counted, not kept (the method does not use them)
};

// Finds the model folder: `dir` itself, `dir/sparse`, or `dir/sparse/0`, the
// first that holds cameras.{txt,bin} and images.{txt,bin}. Empty path if none.
std::filesystem::path FindColmapModel(const std::filesystem::path& dir);

// True if `model_dir` holds cameras.bin and images.bin (ReadColmapModel then reads binary).
bool IsColmapModelBinary(const std::filesystem::path& model_dir);

// Reads text or binary, whichever `model_dir` holds (binary first).
ColmapModel ReadColmapModel(const std::filesystem::path& model_dir);
ColmapModel ReadColmapModelText(const std::filesystem::path& model_dir);
ColmapModel ReadColmapModelBinary(const std::filesystem::path& model_dir);

// Writes cameras, images (with empty 2D point lists) and an empty points3D.
void WriteColmapModelText(const ColmapModel& model, const std::filesystem::path& model_dir);
void WriteColmapModelBinary(const ColmapModel& model, const std::filesystem::path& model_dir);

}  // namespace lfrecon
