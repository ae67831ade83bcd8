#include "synth/degradation.h"

#include <cmath>
#include <random>

#include "synth/texture.h"
#include "util/error.h"

namespace lfrecon::synth {

void DegradationOptions::Check() const {
  LFRECON_CHECK_OPTION(std::isfinite(exposure_drift) && exposure_drift >= 0 && exposure_drift < 1);
  LFRECON_CHECK_OPTION(std::isfinite(exposure_cycles) && exposure_cycles >= 0);
  LFRECON_CHECK_OPTION(std::isfinite(pose_rotation_deg) && pose_rotation_deg >= 0 && pose_rotation_deg <= 10);
  LFRECON_CHECK_OPTION(std::isfinite(pose_translation_mm) && pose_translation_mm >= 0 &&
                       pose_translation_mm <= 1000);
  LFRECON_CHECK_OPTION(std::isfinite(motion_blur) && motion_blur >= 0 && motion_blur <= 1);
  LFRECON_CHECK_OPTION(motion_blur_samples >= 2 && motion_blur_samples <= 64);
}

double ExposureGain(const DegradationOptions& options, int i, int n) {
  if (options.exposure_drift == 0 || n <= 0) return 1.0;
  return 1.0 + options.exposure_drift * std::sin(2.0 * M_PI * options.exposure_cycles * i / n);
}

Rigid3d PerturbPose(const Rigid3d& true_cam_from_world, const DegradationOptions& options, std::uint64_t seed,
                    int i) {
  if (options.pose_rotation_deg == 0 && options.pose_translation_mm == 0) return true_cam_from_world;
  // mt19937_64 is fully specified and Box-Muller is ours, so the error is the
  // same with every standard library (std::normal_distribution is not).
  std::mt19937_64 rng(HashCombine(HashCombine(seed, 0x905E3E11ull), static_cast<std::uint64_t>(i)));
  const auto gauss = [&rng] {
    const double u1 = (static_cast<double>(rng() >> 11) + 0.5) * (1.0 / 9007199254740992.0);
    const double u2 = static_cast<double>(rng() >> 11) * (1.0 / 9007199254740992.0);
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * M_PI * u2);
  };
  const double sr = options.pose_rotation_deg * M_PI / 180.0 / std::sqrt(3.0);
  const double st = options.pose_translation_mm * 1e-3 / std::sqrt(3.0);
  Eigen::Vector3d w, dc;  // one draw at a time: argument order is unspecified in C++
  for (int k = 0; k < 3; ++k) w[k] = sr * gauss();
  for (int k = 0; k < 3; ++k) dc[k] = st * gauss();
  // Perturb the camera's orientation in its own frame and its centre in the world.
  const Eigen::Quaterniond dq =
      w.norm() > 0 ? Eigen::Quaterniond(Eigen::AngleAxisd(w.norm(), w.normalized())) : Eigen::Quaterniond::Identity();
  const Eigen::Vector3d center = CameraCenter(true_cam_from_world) + dc;
  Rigid3d out;
  out.rotation = (dq * true_cam_from_world.rotation).normalized();
  out.translation = -(out.rotation * center);
  return out;
}

Rigid3d InterpolatePose(const Rigid3d& a, const Rigid3d& b, double s) {
  Rigid3d out;
  out.rotation = a.rotation.slerp(s, b.rotation).normalized();
  const Eigen::Vector3d center = (1 - s) * CameraCenter(a) + s * CameraCenter(b);
  out.translation = -(out.rotation * center);
  return out;
}

}  // namespace lfrecon::synth
