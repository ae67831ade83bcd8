#pragma once
// What a real capture does to a clean render, each part deterministic by seed
// and frame index (so frame i is the same whether rendered alone or in a
// stream): a slow exposure drift, motion blur over the shutter interval, and
// the pose error of a good SfM solution in the poses a user is given. Sensor
// noise is RenderOptions::noise_sigma; JPEG compression is the writer's
// format/quality. The figurines-noisy set (BRIEF §3) is noise 0.01, JPEG 80,
// exposure drift 0.04, pose error 0.02° / 0.5 mm.
#include <cstdint>

#include <opencv2/core.hpp>

#include "geometry/rigid3.h"

namespace lfrecon::synth {

struct DegradationOptions {
  // Gain of frame i: 1 + exposure_drift * sin(2π · exposure_cycles · i / n);
  // colours are clipped to [0, 1] afterwards, as a sensor saturates.
  double exposure_drift = 0;
  double exposure_cycles = 1;
  // Per-frame pose error of the *given* poses (sparse/, transforms.json),
  // independent per frame: a rotation about a random axis and a camera-centre
  // offset, each component Gaussian with σ = value / √3, so value is the RMS
  // magnitude (degrees; millimetres). Rendering always uses the true pose.
  double pose_rotation_deg = 0;
  double pose_translation_mm = 0;
  // Shutter open for this fraction of the interval between frames (0: no
  // blur); the frame is the mean of motion_blur_samples renders at poses
  // interpolated across the open interval.
  double motion_blur = 0;
  int motion_blur_samples = 5;

  bool Any() const {
    return exposure_drift != 0 || pose_rotation_deg != 0 || pose_translation_mm != 0 || motion_blur != 0;
  }
  void Check() const;  // throws OptionError
};

// The exposure gain of frame i of n.
double ExposureGain(const DegradationOptions& options, int i, int n);
// `true_cam_from_world` with frame i's pose error (deterministic in seed, i).
Rigid3d PerturbPose(const Rigid3d& true_cam_from_world, const DegradationOptions& options, std::uint64_t seed,
                    int i);
// Pose a fraction `s` in [0, 1] of the way from a to b (slerp; camera centre linear).
Rigid3d InterpolatePose(const Rigid3d& a, const Rigid3d& b, double s);

}  // namespace lfrecon::synth
