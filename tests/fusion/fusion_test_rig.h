#pragma once
// Small synthetic rigs for the fusion tests: analytic scenes rendered with
// exact depth and labels (libs/synth), cameras all around the object.
#include <Eigen/Geometry>
#include <cmath>
#include <vector>

#include "depth/depth_map.h"
#include "geometry/camera.h"
#include "geometry/pinhole_view.h"
#include "geometry/rigid3.h"
#include "synth/renderer.h"
#include "synth/scene.h"

namespace lfrecon::testing {

inline PinholeView LookAtView(const Eigen::Vector3d& eye, const Eigen::Vector3d& target, int width, int height,
                              double hfov_deg) {
  const Eigen::Vector3d dir = (target - eye).normalized();
  const Eigen::Vector3d up = std::abs(dir.z()) > 0.95 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitZ();
  return PinholeView(Camera::PinholeFromHfov(width, height, hfov_deg), LookAt(eye, target, up));
}

// n cameras on a Fibonacci sphere of radius `distance` around `target`.
inline std::vector<PinholeView> SphereRig(int n, const Eigen::Vector3d& target, double distance, int width, int height,
                                          double hfov_deg) {
  std::vector<PinholeView> views;
  const double golden = M_PI * (3.0 - std::sqrt(5.0));
  for (int i = 0; i < n; ++i) {
    const double z = 1.0 - 2.0 * (i + 0.5) / n;
    const double r = std::sqrt(1.0 - z * z);
    const Eigen::Vector3d d(r * std::cos(golden * i), r * std::sin(golden * i), z);
    views.push_back(LookAtView(target + distance * d, target, width, height, hfov_deg));
  }
  return views;
}

// Rings of cameras at the given elevations (degrees) around `target`.
inline std::vector<PinholeView> RingRig(int per_ring, const std::vector<double>& elevations_deg,
                                        const Eigen::Vector3d& target, double distance, int width, int height,
                                        double hfov_deg) {
  std::vector<PinholeView> views;
  for (std::size_t e = 0; e < elevations_deg.size(); ++e) {
    const double el = elevations_deg[e] * M_PI / 180.0;
    for (int i = 0; i < per_ring; ++i) {
      const double az = 2 * M_PI * (i + 0.5 * e) / per_ring;
      const Eigen::Vector3d d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
      views.push_back(LookAtView(target + distance * d, target, width, height, hfov_deg));
    }
  }
  return views;
}

// Exact depth (confidence 1) with labels: foreground where a foreground
// primitive is seen, background elsewhere.
inline DepthMap ExactDepth(const synth::Scene& scene, const PinholeView& view, cv::Mat* image = nullptr) {
  synth::RenderOptions ro;
  ro.supersampling = 1;
  ro.noise_sigma = 0;
  const synth::RenderResult rr = synth::Render(scene, view, ro, 1);
  DepthMap d(view.height, view.width);
  rr.depth.convertTo(d.depth, CV_32F);
  const cv::Mat fg = synth::ForegroundMask(scene, rr.labels);
  for (int r = 0; r < view.height; ++r)
    for (int c = 0; c < view.width; ++c) {
      if (!(d.depth.at<float>(r, c) > 0)) continue;
      d.confidence.at<float>(r, c) = 1.0f;
      d.label.at<std::uint8_t>(r, c) = static_cast<std::uint8_t>(fg.at<std::uint8_t>(r, c) ? DepthLabel::kForeground
                                                                                         : DepthLabel::kBackground);
    }
  if (image) *image = rr.image;
  return d;
}

// A big textured sphere around everything, so every ray hits background.
inline void AddDome(synth::Scene* scene, double radius = 3.0) {
  scene->Add(synth::Primitive::Sphere(Eigen::Vector3d::Zero(), radius,
                                      synth::Material::Noise({0.3f, 0.4f, 0.5f}, {0.8f, 0.8f, 0.85f}, 0.2))
                 .Named("dome"));
}

inline BoundingBox Box(const Eigen::Vector3d& min, const Eigen::Vector3d& max) {
  BoundingBox b;
  b.min = min;
  b.max = max;
  return b;
}

}  // namespace lfrecon::testing
