// `lfrecon poses`: poses for every frame of a video or image folder with
// COLMAP (libs/sfm), written as a dataset folder `lfrecon run` opens.
#include <spdlog/spdlog.h>

#include <cstdio>
#include <memory>
#include <string>

#include "commands.h"
#include "sfm/colmap_poses.h"
#include "util/error.h"

namespace lfrecon::cli {
namespace {

int RunPoses(const ColmapPosesOptions& options) {
  const ColmapPosesSummary s = EstimatePosesWithColmap(options);
  const BoundingBox& V = s.world.volume;
  std::string steps;
  for (const auto& [name, sec] : s.step_seconds) {
    char buf[96];
    std::snprintf(buf, sizeof(buf), "%s%s %.1f s", steps.empty() ? "" : ", ", name.c_str(), sec);
    steps += buf;
  }
  std::printf(
      "poses: %d/%d frames posed (%d/%d keyframes in the SfM model, --step %d) in %.1f s; camera %s "
      "%dx%d f=%.1f px; V = [%.3f %.3f %.3f] - [%.3f %.3f %.3f] from %d of %d sparse points; dataset %s\n"
      "poses: %s\n",
      s.registered, s.frames, s.keyframes_registered, s.keyframes, s.step, s.seconds,
      CameraModelName(s.camera.model).c_str(), s.camera.width, s.camera.height, s.camera.fx(), V.min.x(), V.min.y(),
      V.min.z(), V.max.x(), V.max.y(), V.max.z(), s.world.points_in_volume, s.world.points_total,
      options.out_dir.c_str(), steps.c_str());
  return 0;
}

}  // namespace

void AddPosesCommand(CLI::App& root, int* exit_code) {
  auto* cmd = root.add_subcommand(
      "poses",
      "Poses for every frame of a video or image folder with COLMAP (CPU), written as a dataset folder "
      "lfrecon run opens: images/, sparse/ (up = +z, nominal scale), scene.json with V; COLMAP's workspace "
      "and logs in OUT/colmap/");
  auto o = std::make_shared<ColmapPosesOptions>();
  auto video = std::make_shared<std::string>();
  auto images = std::make_shared<std::string>();
  auto out = std::make_shared<std::string>();
  cmd->add_option("--video", *video, "Input video (any container/codec OpenCV reads)");
  cmd->add_option("--images", *images, "Input image folder (frames in natural name order)");
  cmd->add_option("--out", *out, "Output dataset folder (created)")->required();
  cmd->add_option("--step", o->step,
                  "Every K-th frame goes through SfM; the others are registered to that model (0: automatic, "
                  "every 3rd frame or sparser so that at most --max-keyframes frames go through SfM)")
      ->capture_default_str();
  cmd->add_option("--max-keyframes", o->max_keyframes, "The automatic step's bound on the keyframes")
      ->capture_default_str();
  cmd->add_option("--max-frames", o->max_frames, "Use only the first N frames (0: all)")->capture_default_str();
  cmd->add_option("--colmap", o->colmap, "COLMAP binary")->capture_default_str();
  cmd->add_option("--camera-model", o->camera_model, "One camera for all frames: SIMPLE_RADIAL or PINHOLE")
      ->capture_default_str();
  cmd->add_option("--threads", o->threads, "COLMAP's threads (0: all cores)")->capture_default_str();
  cmd->add_option("--max-features", o->max_num_features, "SIFT features per frame")->capture_default_str();
  cmd->add_option("--overlap", o->overlap, "Sequential matching: each keyframe with its next N keyframes")
      ->capture_default_str();
  cmd->add_option("--loop-pairs", o->loop_pairs,
                  "The first and last N keyframes are matched with each other (closes a loop; 0: off)")
      ->capture_default_str();
  cmd->add_option("--register-neighbours", o->register_neighbours,
                  "Other frames: matched with N keyframes before and N after")
      ->capture_default_str();
  cmd->add_flag("--bundle-adjust", o->bundle_adjust_all, "A final bundle adjustment over every frame (slower)");
  cmd->add_option("--format", o->image_format, "Frames extracted from a video: png or jpg")->capture_default_str();
  cmd->add_option("--camera-distance", o->world.camera_distance,
                  "Scale: the median camera distance from V's centre in the written world (nominal metres)")
      ->capture_default_str();
  cmd->callback([o, video, images, out, exit_code] {
    o->video_path = *video;
    o->images_dir = *images;
    o->out_dir = *out;
    *exit_code = RunPoses(*o);
  });
}

}  // namespace lfrecon::cli
