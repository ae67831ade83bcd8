#pragma once
// Camera paths of the synthetic generator: a circle around a look-at point, a
// rising helix, and a hand-held-style circle with smooth deterministic jitter.
// Pose i depends only on the options and i (never on which frames were made
// before), so frame i is the same whether rendered alone or in a stream.
#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <vector>

#include "geometry/rigid3.h"

namespace lfrecon::synth {

enum class PathType { kCircle, kHelix, kHandheld };

std::string PathTypeName(PathType type);
// "circle", "helix" or "handheld"; throws OptionError naming the choices otherwise.
PathType PathTypeFromName(const std::string& name);

struct CameraPathOptions {
  PathType type = PathType::kCircle;
  int num_frames = 120;
  Eigen::Vector3d target = Eigen::Vector3d::Zero();  // every camera looks at this point
  double radius = 0.9;             // horizontal distance of the camera from the target's vertical axis (m)
  double height = 0.95;            // camera z in world coordinates (helix: height at the middle of the path)
  double start_angle_deg = 0;      // azimuth of frame 0, from +x towards +y
  double loops = 1;                // turns over the whole path; the azimuth step is 360 * loops / num_frames
  double helix_rise = 0.4;         // helix: height gained from first to last frame (m)
  double jitter_position = 0.015;  // handheld: amplitude of the position wobble per axis (m)
  double jitter_rotation_deg = 0.8;  // handheld: amplitude of the orientation wobble per axis (deg)
  std::uint64_t seed = 1;            // handheld: phases of the wobble

  // Throws OptionError when a field is unusable.
  void Check() const;
  // Azimuth step between neighbouring frames in degrees.
  double StepDeg() const { return 360.0 * loops / num_frames; }
};

// cam_from_world of frame i (0 <= i < num_frames); world up is +z.
Rigid3d CameraPathPose(const CameraPathOptions& options, int i);
std::vector<Rigid3d> MakeCameraPath(const CameraPathOptions& options);

}  // namespace lfrecon::synth
