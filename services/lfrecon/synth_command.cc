// `lfrecon synth`: writes a deterministic synthetic dense light field (images,
// poses, exact depth, ground-truth meshes) in the layout of the figurines set.
#include <spdlog/spdlog.h>

#include <cstdio>
#include <memory>
#include <string>

#include "commands.h"
#include "synth/scenes.h"
#include "synth/writer.h"
#include "util/error.h"

namespace lfrecon::cli {
namespace {

struct SynthFlags {
  std::string out;
  synth::SynthOptions options;
  std::string path = "circle";
  std::string format = "png";
  int jpeg_quality = 95;
  int depth_every = 8;
  bool no_meshes = false;
  bool masks = false;
  bool full_aa = false;
};

std::string SceneList() {
  std::string list;
  for (const std::string& n : synth::SceneNames()) list += (list.empty() ? "" : ", ") + n;
  return list;
}

int RunSynth(SynthFlags flags) {
  if (flags.out.empty()) throw OptionError("synth: --out is required");
  bool known = false;
  for (const std::string& n : synth::SceneNames()) known = known || n == flags.options.scene;
  if (!known)
    throw OptionError("synth: unknown scene '" + flags.options.scene + "' (available: " + SceneList() + ")");
  flags.options.path = synth::PathTypeFromName(flags.path);
  flags.options.render.adaptive = !flags.full_aa;
  flags.options.Check();

  synth::SynthWriteOptions write;
  write.out_dir = flags.out;
  write.format = flags.format;
  write.jpeg_quality = flags.jpeg_quality;
  write.depth_every = flags.depth_every;
  write.write_meshes = !flags.no_meshes;
  write.write_masks = flags.masks;
  write.Check();

  const synth::SynthSequence seq = synth::SynthSequence::Create(flags.options);
  spdlog::info(
      "synth: scene '{}', {} frames {}x{}, hfov {:.1f} deg, {} path ({:.3g} loops, {:.3f} deg/frame), seed "
      "{}",
      seq.scene().name(), seq.NumFrames(), seq.camera().width, seq.camera().height, seq.hfov_deg(),
      flags.path, seq.path().loops, seq.path().StepDeg(), seq.seed());
  const synth::SynthWriteSummary s = synth::WriteSynthDataset(seq, write);

  const BoundingBox& V = seq.scene().foreground_bbox();
  std::printf(
      "synth: wrote %d frames of '%s' (%dx%d, %s, seed %llu) to %s in %.1f s (%.0f ms/frame); %d depth maps; "
      "V = [%.3f %.3f %.3f] - [%.3f %.3f %.3f]; gt_mesh %zu triangles, gt_thin %zu\n",
      s.frames, seq.scene().name().c_str(), seq.camera().width, seq.camera().height, flags.path.c_str(),
      static_cast<unsigned long long>(seq.seed()), flags.out.c_str(), s.seconds,
      s.frames > 0 ? 1000.0 * s.seconds / s.frames : 0.0, s.depth_maps, V.min.x(), V.min.y(), V.min.z(),
      V.max.x(), V.max.y(), V.max.z(), s.mesh_triangles, s.thin_triangles);
  return 0;
}

}  // namespace

void AddSynthCommand(CLI::App& root, int* exit_code) {
  auto* cmd = root.add_subcommand(
      "synth",
      "Write a deterministic synthetic dense light field: images/, sparse/ (COLMAP text), transforms.json, "
      "depth/depth_NNNN.exr (exact planar depth), gt_mesh.ply, gt_thin.ply, scene.json");
  auto flags = std::make_shared<SynthFlags>();
  synth::SynthOptions& o = flags->options;
  cmd->add_option("--out", flags->out, "Output folder (created; existing files are overwritten)")->required();
  cmd->add_option("--scene", o.scene, "Scene: " + SceneList())->capture_default_str();
  cmd->add_option("--frames", o.frames, "Number of frames")->capture_default_str();
  cmd->add_option("--width", o.width, "Image width in pixels")->capture_default_str();
  cmd->add_option("--height", o.height, "Image height in pixels")->capture_default_str();
  cmd->add_option("--hfov", o.hfov_deg, "Horizontal field of view in degrees (PINHOLE, cx = W/2, cy = H/2)")
      ->capture_default_str();
  cmd->add_option("--seed", o.seed, "Seed of the textures, the image noise and the hand-held wobble")
      ->capture_default_str();
  cmd->add_option("--path", flags->path,
                  "Camera path: circle (around V's centre), helix (rising, 3 loops by default), handheld "
                  "(circle with smooth jitter)")
      ->capture_default_str();
  cmd->add_option(
         "--loops", o.loops,
         "Turns over the whole sequence; 0 = the scene's default (1, or a 60-degree arc for 'plane'; 3 "
         "for helix)")
      ->capture_default_str();
  cmd->add_option("--depth-every", flags->depth_every,
                  "Write depth/depth_NNNN.exr for every K-th frame (0: none)")
      ->capture_default_str();
  cmd->add_option("--format", flags->format, "Image format: png or jpg")->capture_default_str();
  cmd->add_option("--noise", o.render.noise_sigma, "Gaussian noise sigma per channel, colours in [0, 1]")
      ->capture_default_str();
  cmd->add_flag("--masks", flags->masks,
                "Also write masks/NNNNN.png: 255 where a pixel's centre sees the objects (not the table or walls)");
  cmd->add_option("--jpeg-quality", flags->jpeg_quality, "JPEG quality of --format jpg (1-100)")
      ->capture_default_str();
  cmd->add_option("--exposure-drift", o.degradation.exposure_drift,
                  "Relative amplitude of a sinusoidal exposure gain over the sequence (0.04: +-4 %)")
      ->capture_default_str();
  cmd->add_option("--exposure-cycles", o.degradation.exposure_cycles, "Periods of the exposure drift over the sequence")
      ->capture_default_str();
  cmd->add_option("--pose-rot-deg", o.degradation.pose_rotation_deg,
                  "Per-frame rotation error (RMS, degrees) of the written poses; frames render from the true poses, "
                  "which scene.json keeps")
      ->capture_default_str();
  cmd->add_option("--pose-trans-mm", o.degradation.pose_translation_mm,
                  "Per-frame camera-centre error (RMS, mm) of the written poses")
      ->capture_default_str();
  cmd->add_option("--motion-blur", o.degradation.motion_blur,
                  "Shutter open for this fraction of the interval between frames (0: none; rendered as the mean "
                  "of --motion-blur-samples renders)")
      ->capture_default_str();
  cmd->add_option("--motion-blur-samples", o.degradation.motion_blur_samples, "Renders averaged per blurred frame")
      ->capture_default_str();
  cmd->add_option("--supersampling", o.render.supersampling, "S x S samples per pixel")
      ->capture_default_str();
  cmd->add_flag(
      "--full-aa", flags->full_aa,
      "Box-filter every pixel over all S x S samples (about 3x slower); by default pixels inside a "
      "surface take one texture sample pre-filtered to the pixel, and only edge pixels average samples");
  cmd->add_flag("--no-meshes", flags->no_meshes, "Do not write gt_mesh.ply and gt_thin.ply");
  cmd->callback([flags, exit_code] { *exit_code = RunSynth(*flags); });
}

}  // namespace lfrecon::cli
