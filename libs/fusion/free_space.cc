#include "fusion/free_space.h"

#include <algorithm>
#include <opencv2/imgproc.hpp>

namespace lfrecon {

DepthMap WithGatedBackgroundFloor(const DepthMap& map, const PinholeView& view, const BoundingBox& volume,
                                  double floor, double gate_px, const cv::Mat& protect) {
  if (!(floor > 0) || map.depth.empty()) return map;
  DepthMap out;
  out.depth = map.depth;
  out.label = map.label;
  out.confidence = map.confidence.empty() ? cv::Mat(map.depth.size(), CV_32F, cv::Scalar(1.0f)) : map.confidence.clone();
  const bool labels = map.label.size() == map.depth.size();
  constexpr auto kFg = static_cast<std::uint8_t>(DepthLabel::kForeground);
  constexpr auto kBg = static_cast<std::uint8_t>(DepthLabel::kBackground);
  // 0 = foreground depth, 1 = background depth, 2 = nothing.
  cv::Mat kind(map.depth.size(), CV_8U, cv::Scalar(2));
  for (int r = 0; r < map.depth.rows; ++r) {
    const float* d = map.depth.ptr<float>(r);
    const std::uint8_t* l = labels ? map.label.ptr<std::uint8_t>(r) : nullptr;
    std::uint8_t* k = kind.ptr<std::uint8_t>(r);
    for (int c = 0; c < map.depth.cols; ++c) {
      if (!(d[c] > 0)) continue;
      // Only a ray that passes V to a background beyond it is raised: a
      // background-labelled depth inside V (a thin part the propagation
      // labelled background) counts as foreground here, as it does without labels.
      const bool inside = volume.Contains(view.Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), d[c]));
      if ((l && l[c] == kFg) || inside) k[c] = 0;
      else if (!l || l[c] == kBg) k[c] = 1;
    }
  }
  cv::Mat dist;  // pixels to the nearest foreground depth
  if (gate_px > 0) {
    cv::Mat not_fg = kind != 0;  // 255 where not foreground
    if (protect.size() == kind.size()) not_fg.setTo(0, protect);
    cv::distanceTransform(not_fg, dist, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  }
  const float f = static_cast<float>(floor), g = static_cast<float>(gate_px);
  for (int r = 0; r < map.depth.rows; ++r) {
    const std::uint8_t* k = kind.ptr<std::uint8_t>(r);
    float* cf = out.confidence.ptr<float>(r);
    const float* dd = dist.empty() ? nullptr : dist.ptr<float>(r);
    for (int c = 0; c < map.depth.cols; ++c)
      if (k[c] == 1 && cf[c] < f && (!dd || dd[c] >= g)) cf[c] = f;
  }
  return out;
}

DepthMap WithMaskFreeSpace(const DepthMap& map, const cv::Mat& mask, double confidence, double margin_px) {
  if (!(confidence > 0) || map.depth.empty() || mask.size() != map.depth.size() || mask.type() != CV_8U) return map;
  DepthMap out;
  out.depth = map.depth.clone();
  out.label = map.label.size() == map.depth.size() ? map.label.clone() : cv::Mat::zeros(map.depth.size(), CV_8U);
  out.confidence = map.confidence.size() == map.depth.size() ? map.confidence.clone()
                                                             : cv::Mat(map.depth.size(), CV_32F, cv::Scalar(1.0f));
  cv::Mat not_object = mask == 0, dist;  // distance to the nearest object pixel
  cv::distanceTransform(not_object, dist, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  constexpr auto kBg = static_cast<std::uint8_t>(DepthLabel::kBackground);
  const float c_min = static_cast<float>(confidence), margin = static_cast<float>(margin_px);
  for (int r = 0; r < map.depth.rows; ++r) {
    const float* dd = dist.ptr<float>(r);
    float* d = out.depth.ptr<float>(r);
    float* cf = out.confidence.ptr<float>(r);
    std::uint8_t* l = out.label.ptr<std::uint8_t>(r);
    for (int c = 0; c < map.depth.cols; ++c) {
      if (!(dd[c] > margin)) continue;
      const bool was_background = l[c] == kBg;
      d[c] = 0;
      l[c] = kBg;
      cf[c] = was_background ? std::max(cf[c], c_min) : c_min;
    }
  }
  return out;
}

}  // namespace lfrecon
