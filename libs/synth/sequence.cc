#include "synth/sequence.h"

#include <cmath>
#include <cstdio>

#include "synth/gt_mesh.h"
#include "synth/texture.h"
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
  degradation.Check();
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
                       options.render, options.seed, options.degradation);
}

SynthSequence::SynthSequence(Scene scene, Camera camera, CameraPathOptions path, RenderOptions render,
                             std::uint64_t seed, DegradationOptions degradation)
    : scene_(std::move(scene)),
      camera_(std::move(camera)),
      path_(path),
      render_(render),
      seed_(seed),
      degradation_(degradation) {
  const std::string problem = camera_.Validate();
  if (!problem.empty()) throw OptionError("synth: bad camera: " + problem);
  if (camera_.HasDistortion()) throw OptionError("synth: the camera must be distortion-free");
  render_.Check();
  degradation_.Check();
  poses_ = MakeCameraPath(path_);
  given_poses_.reserve(poses_.size());
  for (int i = 0; i < NumFrames(); ++i)
    given_poses_.push_back(PerturbPose(poses_[static_cast<std::size_t>(i)], degradation_, seed_, i));
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
  const DegradationOptions& d = degradation_;
  if (d.motion_blur == 0 && d.exposure_drift == 0) return synth::Render(scene_, View(i), render_, FrameSeed(i));

  // Blur and gain act on the light before the sensor's noise and 8-bit
  // levels; with blur the mean of K renders carries noise σ·√K/√K = σ.
  RenderOptions sub = render_;
  sub.quantize = false;
  RenderResult out;
  if (d.motion_blur > 0) {
    const int K = d.motion_blur_samples;
    sub.noise_sigma = render_.noise_sigma * std::sqrt(static_cast<double>(K));
    cv::Mat sum;
    for (int k = 0; k < K; ++k) {
      // Shutter time t in [i - F/2, i + F/2] (frame units), between path poses.
      const double t = i + d.motion_blur * ((k + 0.5) / K - 0.5);
      const int j = static_cast<int>(std::floor(t));
      const Rigid3d pose =
          InterpolatePose(CameraPathPose(path_, j), CameraPathPose(path_, j + 1), t - j);
      RenderResult r = synth::Render(scene_, PinholeView(camera_, pose), sub,
                                     HashCombine(FrameSeed(i), static_cast<std::uint64_t>(k + 1)));
      if (k == 0)
        sum = r.image.clone();
      else
        sum += r.image;
    }
    out.image = sum / static_cast<double>(K);
    // Depth and labels of the frame's own (true) pose.
    const RenderResult centre = synth::Render(scene_, View(i), [&] {
      RenderOptions o = sub;
      o.noise_sigma = 0;
      return o;
    }(), FrameSeed(i));
    out.depth = centre.depth;
    out.labels = centre.labels;
    out.mixed = centre.mixed;
  } else {
    out = synth::Render(scene_, View(i), sub, FrameSeed(i));
  }
  const double gain = ExposureGain(d, i, NumFrames());
  if (gain != 1.0) out.image *= gain;
  cv::min(out.image, 1.0, out.image);
  cv::max(out.image, 0.0, out.image);
  if (render_.quantize) {
    out.image.convertTo(out.image, CV_8UC3, 255.0);
    out.image.convertTo(out.image, CV_32FC3, 1.0 / 255.0);
  }
  return out;
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
