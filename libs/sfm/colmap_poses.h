#pragma once
// Poses for every frame of a video or image sequence with COLMAP (Debian's
// `colmap` 3.8, CPU) driven as a subprocess, written as a dataset folder that
// `lfrecon run` opens: images/, sparse/ (COLMAP text, normalised world:
// up = +z, origin at V's bottom centre, nominal scale), scene.json with V.
//
// Only every `step`-th frame goes through incremental SfM (feature_extractor
// with one shared camera, sequential_matcher, a few loop-closure pairs, mapper);
// the other frames are then extracted with the same camera, matched with their
// nearest keyframes only and registered to the keyframe model
// (image_registrator), so a long video does not pay for SfM on every frame.
// COLMAP's workspace and per-step logs stay in OUT/colmap/.
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "sfm/world_frame.h"

namespace lfrecon {

struct ColmapPosesOptions {
  std::filesystem::path video_path;  // frames from a video (OpenCV VideoCapture) ...
  std::filesystem::path images_dir;  // ... or from an image folder (natural name order)
  std::filesystem::path out_dir;     // the dataset folder written
  // Every step-th frame is a keyframe (SfM); the rest are registered. 0:
  // automatic, KeyframeStep(frames, max_keyframes).
  int step = 0;
  // The automatic step keeps at most this many keyframes: the mapper's time
  // grows faster than linearly with them (161 keyframes: ~450 s of the 480-frame
  // loop's 1365 s), registration only linearly with the other frames.
  int max_keyframes = 160;
  int max_frames = 0;                // use only the first N frames (0: all)
  std::string colmap = "colmap";     // the COLMAP binary (looked up in PATH without a '/')
  std::string camera_model = "SIMPLE_RADIAL";  // one camera for all frames: SIMPLE_RADIAL or PINHOLE
  int threads = 0;                   // COLMAP's threads (0: all cores)
  int max_num_features = 2048;       // SIFT features per frame (CPU matching cost grows with its square)
  int overlap = 3;                   // keyframe k is matched with keyframes k+1 .. k+overlap
  int loop_pairs = 3;                // the first and last loop_pairs keyframes are matched too (closes loops; 0: off)
  int register_neighbours = 1;       // other frames: matched with this many keyframes before and after
  bool bundle_adjust_all = false;    // a final bundle adjustment over every frame (slower)
  std::string image_format = "png";  // frames extracted from a video: png or jpg (quality 95)
  WorldFrameOptions world;

  // Throws OptionError naming the field.
  void Check() const;
};

struct ColmapPosesSummary {
  int frames = 0;
  int keyframes = 0;
  int keyframes_registered = 0;  // in the keyframe model
  int registered = 0;            // frames with a pose in the dataset
  std::vector<std::string> unregistered;
  std::vector<std::pair<std::string, double>> step_seconds;  // frames, feature_extractor, ... in order
  double seconds = 0;
  int step = 0;  // the step used (the automatic one when options.step is 0)
  WorldFrame world;
  Camera camera;  // the estimated camera (normalised world: unchanged intrinsics)
};

// The automatic keyframe step: every 3rd frame (the step measured on a
// 0.75-degree loop), or sparser so that at most max_keyframes frames go through
// SfM: ceil(frames / max_keyframes). A 3000-frame video gets 19 (a 0.12-degree
// loop: keyframes ~2.3 degrees apart, as the 480-frame loop's at step 3).
int KeyframeStep(int frames, int max_keyframes);

// Throws ExternalToolError naming the binary when COLMAP is missing or a step
// fails (with its exit status and last output lines), InputError for an
// unreadable video/image folder or a model without usable frames.
ColmapPosesSummary EstimatePosesWithColmap(const ColmapPosesOptions& options);

}  // namespace lfrecon
