#pragma once
// Which neighbour frames the photometric checks of this library use (§4.1
// photoconsistency and the dense consistency check).
#include <algorithm>
#include <cmath>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
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

// The colours the photometric checks read: `smoothed` when it is a CV_32FC3
// copy of `image`'s size, else `image`.
inline const cv::Mat& PhotometricColours(const ViewImage& v) {
  return !v.smoothed.empty() && v.smoothed.size() == v.image.size() && v.smoothed.type() == CV_32FC3 ? v.smoothed
                                                                                                    : v.image;
}

// Grey levels of PhotometricColours(v) (CV_32F): the frame's own `grey`
// (PrepareViewImage, of `smoothed`) when it has one, else computed the same way.
inline cv::Mat PhotometricGrey(const ViewImage& v) {
  const cv::Mat& colours = PhotometricColours(v);
  if (&colours == &v.smoothed && v.grey.size() == v.smoothed.size() && v.grey.type() == CV_32F) return v.grey;
  cv::Mat grey;
  cv::cvtColor(colours, grey, cv::COLOR_BGR2GRAY);
  return grey;
}

// Degrees between the viewing directions, or a negative value when `nb` is
// not to be used with `ref` (beyond the angle, or at the reference's centre).
inline double UsableAngle(const PinholeView& ref, const PinholeView& nb, double max_angle_deg) {
  const double angle = AngleBetweenDeg(ref.ViewingDirection(), nb.ViewingDirection());
  if (angle > max_angle_deg) return -1;
  if ((nb.Center() - ref.Center()).norm() < 1e-9) return -1;  // the reference itself
  return angle;
}

// Which side of the reference a neighbour's centre lies on (its camera x axis): 0 or 1.
inline int SideOf(const PinholeView& reference, const PinholeView& nb) {
  return (reference.R * nb.Center() + reference.t).x() >= 0 ? 0 : 1;
}

// At most `count` of `neighbors` (indices; null entries skipped) within
// max_view_angle_deg, the widest baselines first, alternating between the
// reference's two sides so both are represented where both have views.
inline std::vector<int> WidestNeighbors(const PinholeView& reference, const std::vector<const PinholeView*>& neighbors,
                                        double max_view_angle_deg, int count) {
  std::vector<std::pair<double, int>> side[2];
  for (std::size_t j = 0; j < neighbors.size(); ++j) {
    if (!neighbors[j]) continue;
    const double angle = UsableAngle(reference, *neighbors[j], max_view_angle_deg);
    if (angle < 0) continue;
    side[SideOf(reference, *neighbors[j])].emplace_back(angle, static_cast<int>(j));
  }
  for (auto& s : side)
    std::stable_sort(s.begin(), s.end(), [](const auto& x, const auto& y) { return x.first > y.first; });
  std::vector<int> out;
  std::size_t k[2] = {0, 0};
  while (static_cast<int>(out.size()) < count && (k[0] < side[0].size() || k[1] < side[1].size())) {
    for (int s = 0; s < 2 && static_cast<int>(out.size()) < count; ++s)
      if (k[s] < side[s].size()) out.push_back(side[s][k[s]++].second);
  }
  return out;
}

}  // namespace lfrecon
