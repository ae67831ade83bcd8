#include "synth/camera_path.h"

#include <Eigen/Geometry>
#include <cmath>

#include "synth/texture.h"
#include "util/error.h"

namespace lfrecon::synth {
namespace {

// A smooth wobble in [-1, 1]-ish: three incommensurate sinusoids of the path
// parameter (in turns), phases from the seed. Frequencies of a few cycles per
// turn keep neighbouring frames of a dense sequence close together.
double Wobble(std::uint64_t seed, int channel, double turns) {
  static constexpr double kFreq[3] = {2.3, 5.1, 11.7};
  static constexpr double kAmp[3] = {0.6, 0.3, 0.15};
  double v = 0;
  for (int k = 0; k < 3; ++k) {
    const double phase =
        2.0 * M_PI * HashToUnit(HashCombine(seed, static_cast<std::uint64_t>(channel * 3 + k)));
    v += kAmp[k] * std::sin(2.0 * M_PI * kFreq[k] * turns + phase);
  }
  return v;
}

}  // namespace

std::string PathTypeName(PathType type) {
  switch (type) {
    case PathType::kCircle:
      return "circle";
    case PathType::kHelix:
      return "helix";
    case PathType::kHandheld:
      return "handheld";
  }
  return "unknown";
}

PathType PathTypeFromName(const std::string& name) {
  for (PathType t : {PathType::kCircle, PathType::kHelix, PathType::kHandheld})
    if (PathTypeName(t) == name) return t;
  throw OptionError("unknown camera path '" + name + "' (choose circle, helix or handheld)");
}

void CameraPathOptions::Check() const {
  LFRECON_CHECK_OPTION(num_frames > 0);
  LFRECON_CHECK_OPTION(target.allFinite());
  LFRECON_CHECK_OPTION(std::isfinite(radius) && radius > 0);
  LFRECON_CHECK_OPTION(std::isfinite(height));
  LFRECON_CHECK_OPTION(std::isfinite(start_angle_deg));
  LFRECON_CHECK_OPTION(std::isfinite(loops) && loops > 0);
  LFRECON_CHECK_OPTION(std::isfinite(helix_rise));
  LFRECON_CHECK_OPTION(std::isfinite(jitter_position) && jitter_position >= 0);
  LFRECON_CHECK_OPTION(std::isfinite(jitter_rotation_deg) && jitter_rotation_deg >= 0);
}

Rigid3d CameraPathPose(const CameraPathOptions& o, int i) {
  const double turns = o.loops * static_cast<double>(i) / o.num_frames;
  const double azimuth = o.start_angle_deg * M_PI / 180.0 + 2.0 * M_PI * turns;
  Eigen::Vector3d eye(o.target.x() + o.radius * std::cos(azimuth),
                      o.target.y() + o.radius * std::sin(azimuth), o.height);
  if (o.type == PathType::kHelix) {
    const double f = o.num_frames > 1 ? static_cast<double>(i) / (o.num_frames - 1) : 0.5;
    eye.z() += (f - 0.5) * o.helix_rise;
  }
  if (o.type != PathType::kHandheld) return LookAt(eye, o.target, Eigen::Vector3d::UnitZ());

  for (int k = 0; k < 3; ++k) eye[k] += o.jitter_position * Wobble(o.seed, k, turns);
  const Rigid3d base = LookAt(eye, o.target, Eigen::Vector3d::UnitZ());
  const double s = o.jitter_rotation_deg * M_PI / 180.0;
  const Eigen::Vector3d w(s * Wobble(o.seed, 3, turns), s * Wobble(o.seed, 4, turns),
                          s * Wobble(o.seed, 5, turns));
  const Eigen::Quaterniond jitter(
      Eigen::AngleAxisd(w.norm(), w.norm() > 0 ? Eigen::Vector3d(w.normalized()) : Eigen::Vector3d::UnitZ()));
  const Eigen::Quaterniond q = (jitter * base.rotation).normalized();
  return Rigid3d(q, -(q * eye));
}

std::vector<Rigid3d> MakeCameraPath(const CameraPathOptions& options) {
  options.Check();
  std::vector<Rigid3d> poses;
  poses.reserve(static_cast<std::size_t>(options.num_frames));
  for (int i = 0; i < options.num_frames; ++i) poses.push_back(CameraPathPose(options, i));
  return poses;
}

}  // namespace lfrecon::synth
