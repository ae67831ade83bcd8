#include "synth/sequence.h"

#include <cmath>
#include <cstdio>

#include "synth/gt_mesh.h"
#include "synth/scenes.h"
#include "util/error.h"

namespace lfrecon::synth {

void SynthOptions::Check() const {
  LFRECON_CHECK_OPTION(frames > 0);
  LFRECON_CHECK_OPTION(width > 0 && width <= 16384);
  LFRECON_CHECK_OPTION(height > 0 && height <= 16384);
  LFRECON_CHECK_OPTION(std::isfinite(hfov_deg) && hfov_deg > 0 && hfov_deg < 180);
  LFRECON_CHECK_OPTION(std::isfinite(loops) && loops >= 0);
  render.Check();
}

SynthSequence SynthSequence::Create(const SynthOptions& options) {
  options.Check();
  SceneSetup setup = MakeNamedScene(options.scene, options.seed);
  CameraPathOptions path = setup.path;
  path.type = options.path;
  path.num_frames = options.frames;
  path.seed = options.seed;
  if (options.loops > 0)
    path.loops = options.loops;
  else if (options.path == PathType::kHelix)
    path.loops = 3;
  return SynthSequence(std::move(setup.scene),
                       Camera::PinholeFromHfov(options.width, options.height, options.hfov_deg), path,
                       options.render, options.seed);
}

SynthSequence::SynthSequence(Scene scene, Camera camera, CameraPathOptions path, RenderOptions render,
                             std::uint64_t seed)
    : scene_(std::move(scene)), camera_(std::move(camera)), path_(path), render_(render), seed_(seed) {
  const std::string problem = camera_.Validate();
  if (!problem.empty()) throw OptionError("synth: bad camera: " + problem);
  if (camera_.HasDistortion()) throw OptionError("synth: the camera must be distortion-free");
  render_.Check();
  poses_ = MakeCameraPath(path_);
}

double SynthSequence::hfov_deg() const {
  return 2.0 * std::atan(0.5 * camera_.width / camera_.fx()) * 180.0 / M_PI;
}

std::string SynthSequence::ImageName(int i, const std::string& ext) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%05d.", i);
  return buf + ext;
}

std::uint64_t SynthSequence::FrameSeed(int i) const {
  return HashCombine(HashCombine(seed_, 0xF4A3E5ull), static_cast<std::uint64_t>(i));
}

RenderResult SynthSequence::Render(int i) const {
  if (i < 0 || i >= NumFrames())
    throw std::out_of_range("synth: frame " + std::to_string(i) + " out of range [0, " +
                            std::to_string(NumFrames()) + ")");
  return synth::Render(scene_, View(i), render_, FrameSeed(i));
}

TriangleMesh SynthSequence::GroundTruthMesh(bool thin_only) const {
  return synth::GroundTruthMesh(scene_, thin_only);
}

std::unique_ptr<FrameSource> SynthSequence::OpenFrames(const std::string& ext) const {
  return std::make_unique<SynthFrameSource>(std::make_shared<const SynthSequence>(*this), ext);
}

SynthFrameSource::SynthFrameSource(std::shared_ptr<const SynthSequence> sequence, std::string ext)
    : sequence_(std::move(sequence)), ext_(std::move(ext)) {}

bool SynthFrameSource::Next(Frame* frame) {
  if (next_ >= sequence_->NumFrames()) return false;
  *frame = Read(next_);
  ++next_;
  return true;
}

Frame SynthFrameSource::Read(int index) {
  if (index < 0 || index >= sequence_->NumFrames())
    throw InputError("synth:" + sequence_->scene().name(), "frame " + std::to_string(index) +
                                                               " out of range [0, " +
                                                               std::to_string(sequence_->NumFrames()) + ")");
  Frame frame;
  frame.index = index;
  frame.name = SynthSequence::ImageName(index, ext_);
  frame.image = sequence_->RenderImage(index);
  return frame;
}

}  // namespace lfrecon::synth
