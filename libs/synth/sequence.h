#pragma once
// A synthetic dense light field: a scene, one PINHOLE camera, a camera path
// and render settings. Frame i (image, exact depth, labels) is rendered on
// demand and depends only on (scene, camera, pose i, render options, seed, i),
// so it is identical whether rendered alone or in a stream.
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "geometry/camera.h"
#include "geometry/pinhole_view.h"
#include "geometry/rigid3.h"
#include "geometry/triangle_mesh.h"
#include "io/frame_source.h"
#include "synth/camera_path.h"
#include "synth/degradation.h"
#include "synth/renderer.h"
#include "synth/scene.h"

namespace lfrecon::synth {

struct SynthOptions {
  std::string scene = "tabletop";  // one of SceneNames()
  std::uint64_t seed = 1;
  int frames = 120;
  int width = 640;
  int height = 360;
  double hfov_deg = 55.0;
  PathType path = PathType::kCircle;
  double loops = 0;  // turns of the path; 0: the scene's default (circle/handheld), 3 for a helix
  RenderOptions render;
  DegradationOptions degradation;  // exposure drift, motion blur, pose error of the given poses

  void Check() const;  // throws OptionError
};

class SynthSequence {
 public:
  // Builds the named scene with its suggested rig; options.path/frames/loops override it.
  static SynthSequence Create(const SynthOptions& options);
  // Any scene and path (e.g. a test's own scene); poses come from `path`.
  SynthSequence(Scene scene, Camera camera, CameraPathOptions path, RenderOptions render, std::uint64_t seed,
                DegradationOptions degradation = {});

  int NumFrames() const { return static_cast<int>(poses_.size()); }
  const Scene& scene() const { return scene_; }
  const Camera& camera() const { return camera_; }  // the same for every frame
  const CameraPathOptions& path() const { return path_; }
  const RenderOptions& render_options() const { return render_; }
  std::uint64_t seed() const { return seed_; }
  double hfov_deg() const;

  const DegradationOptions& degradation() const { return degradation_; }

  // The true pose of frame i (what it is rendered from).
  const Rigid3d& cam_from_world(int i) const { return poses_.at(static_cast<std::size_t>(i)); }
  const std::vector<Rigid3d>& poses() const { return poses_; }
  // The pose a user is given for frame i: the true one with the degradation's
  // pose error (equal to cam_from_world without one). The writer writes these.
  const Rigid3d& given_cam_from_world(int i) const { return given_poses_.at(static_cast<std::size_t>(i)); }
  const std::vector<Rigid3d>& given_poses() const { return given_poses_; }
  PinholeView View(int i) const { return PinholeView(camera_, cam_from_world(i)); }
  // "00042.png" (ext without the dot).
  static std::string ImageName(int i, const std::string& ext = "png");
  // The noise seed of frame i.
  std::uint64_t FrameSeed(int i) const;

  // Frame i from its true pose, with the degradation's motion blur and
  // exposure gain (depth and labels stay those of the true pose).
  RenderResult Render(int i) const;
  cv::Mat RenderImage(int i) const { return Render(i).image; }

  TriangleMesh GroundTruthMesh(bool thin_only = false) const;

  // Frames rendered on demand (nothing on disk); names use `ext`.
  std::unique_ptr<FrameSource> OpenFrames(const std::string& ext = "png") const;

 private:
  Scene scene_;
  Camera camera_;
  CameraPathOptions path_;
  RenderOptions render_;
  std::uint64_t seed_ = 1;
  DegradationOptions degradation_;
  std::vector<Rigid3d> poses_;
  std::vector<Rigid3d> given_poses_;
};

// A FrameSource that renders each frame when it is asked for.
class SynthFrameSource : public FrameSource {
 public:
  explicit SynthFrameSource(std::shared_ptr<const SynthSequence> sequence, std::string ext = "png");
  int NumFrames() const override { return sequence_->NumFrames(); }
  bool Next(Frame* frame) override;
  Frame Read(int index) override;  // throws InputError for a bad index

 private:
  std::shared_ptr<const SynthSequence> sequence_;
  std::string ext_;
  int next_ = 0;
};

}  // namespace lfrecon::synth
