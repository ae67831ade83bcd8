#pragma once
// Writes a synthetic sequence to disk in the layout of ../shared/data/figurines:
//   images/NNNNN.png|jpg, sparse/{cameras,images,points3D}.txt (COLMAP text,
//   world-to-camera, OpenCV axes), transforms.json (NeRF, camera-to-world,
//   OpenGL axes), depth/depth_NNNN.exr (planar depth, metres, float32, every
//   k-th frame, NNNN = sequence index), gt_mesh.ply, gt_thin.ply, scene.json,
//   and optionally masks/NNNNN.png.
#include <filesystem>
#include <string>

#include "synth/sequence.h"

namespace lfrecon::synth {

struct SynthWriteOptions {
  std::filesystem::path out_dir;
  std::string format = "png";  // png | jpg
  int jpeg_quality = 95;
  int depth_every = 8;  // write depth for frames 0, k, 2k, ...; 0: none
  bool write_meshes = true;
  // masks/NNNNN.png: 255 where a pixel's centre sees a foreground primitive
  // (ForegroundMask), 0 elsewhere, as an object mask from a segmenter would be.
  bool write_masks = false;

  void Check() const;  // throws OptionError
};

struct SynthWriteSummary {
  int frames = 0;
  int depth_maps = 0;
  std::size_t mesh_triangles = 0;
  std::size_t thin_triangles = 0;
  double seconds = 0;
};

// Renders and writes every frame (frames in parallel); logs a progress line.
// Throws InputError naming a file that cannot be written.
SynthWriteSummary WriteSynthDataset(const SynthSequence& sequence, const SynthWriteOptions& options);

// Path of the ground-truth depth map of sequence index i: depth/depth_NNNN.exr.
std::filesystem::path SynthDepthPath(const std::filesystem::path& out_dir, int i);

}  // namespace lfrecon::synth
