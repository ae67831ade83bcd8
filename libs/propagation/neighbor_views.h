#pragma once
// Which neighbour frames the photometric checks of this library use (§4.1
// photoconsistency and the dense consistency check).
#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>

#include "depth/gradient_depth_estimator.h"
#include "geometry/pinhole_view.h"

namespace lfrecon {

// A frame the checks can read: present and CV_32FC3.
inline bool UsableImage(const ViewImage* v) { return v && !v->image.empty() && v->image.type() == CV_32FC3; }

// Degrees between the viewing directions, or a negative value when `nb` is
// not to be used with `ref` (beyond the angle, or at the reference's centre).
inline double UsableAngle(const PinholeView& ref, const PinholeView& nb, double max_angle_deg) {
  const double cosang = std::clamp(ref.ViewingDirection().dot(nb.ViewingDirection()), -1.0, 1.0);
  const double angle = std::acos(cosang) * 180.0 / M_PI;
  if (angle > max_angle_deg) return -1;
  if ((nb.Center() - ref.Center()).norm() < 1e-9) return -1;  // the reference itself
  return angle;
}

}  // namespace lfrecon
