#pragma once
// Which neighbour frames the photometric checks of this library use (§4.1
// photoconsistency and the dense consistency check).
#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <vector>

#include "depth/gradient_depth_estimator.h"
#include "geometry/pinhole_view.h"

namespace lfrecon {

// A frame the checks can read: present and CV_32FC3.
inline bool UsableImage(const ViewImage* v) { return v && !v->image.empty() && v->image.type() == CV_32FC3; }

// The neighbours with a usable frame, in their order, and their views: what
// the checks' SelectNeighbors index (neighbours without a frame take no part).
struct UsableNeighbors {
  std::vector<const ViewImage*> images;
  std::vector<const PinholeView*> views;
};
inline UsableNeighbors FindUsableNeighbors(const std::vector<const ViewImage*>& neighbors) {
  UsableNeighbors out;
  for (const ViewImage* v : neighbors)
    if (UsableImage(v)) {
      out.images.push_back(v);
      out.views.push_back(&v->view);
    }
  return out;
}

// Degrees between the viewing directions, or a negative value when `nb` is
// not to be used with `ref` (beyond the angle, or at the reference's centre).
inline double UsableAngle(const PinholeView& ref, const PinholeView& nb, double max_angle_deg) {
  const double angle = AngleBetweenDeg(ref.ViewingDirection(), nb.ViewingDirection());
  if (angle > max_angle_deg) return -1;
  if ((nb.Center() - ref.Center()).norm() < 1e-9) return -1;  // the reference itself
  return angle;
}

}  // namespace lfrecon
