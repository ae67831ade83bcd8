#pragma once
// Test helper: renders a reference view and its neighbours of a synthetic
// dense light field (480 frames per loop, 0.75° apart), with ground truth.
#include <memory>
#include <opencv2/imgproc.hpp>
#include <vector>

#include "depth/gradient_depth_estimator.h"
#include "geometry/view_graph.h"
#include "synth/renderer.h"
#include "synth/scenes.h"
#include "synth/sequence.h"

namespace lfrecon::testing {

struct SynthViews {
  std::shared_ptr<synth::SynthSequence> sequence;
  BoundingBox volume;
  int reference = 0;
  std::vector<int> neighbor_ids;  // within `angle` of the reference, by angle
  ViewImage ref;
  std::vector<ViewImage> neighbors;
  synth::RenderResult truth;  // of the reference
  cv::Mat foreground;         // CV_8U, 255 where the reference sees a foreground primitive
  cv::Mat near_edge;          // CV_8U, 255 within 2 px of a pixel whose samples mix primitives

  std::vector<const ViewImage*> NeighborPtrs() const {
    std::vector<const ViewImage*> out;
    for (const auto& n : neighbors) out.push_back(&n);
    return out;
  }
};

// Renders `reference` of `sequence`, its views within `angle` and the ground truth.
inline SynthViews MakeSynthViewsOf(std::shared_ptr<synth::SynthSequence> sequence, int reference = 0,
                                   double angle = 5.0) {
  SynthViews v;
  v.sequence = std::move(sequence);
  v.volume = v.sequence->scene().foreground_bbox();
  v.reference = reference;
  std::vector<Eigen::Vector3d> dirs;
  for (int i = 0; i < v.sequence->NumFrames(); ++i) dirs.push_back(v.sequence->View(i).ViewingDirection());
  const ViewGraph graph(dirs, angle);
  v.neighbor_ids = graph.Neighbors(reference);
  v.truth = v.sequence->Render(reference);
  v.ref = ViewImage{v.sequence->View(reference), v.truth.image, cv::Mat(), cv::Mat()};
  for (int j : v.neighbor_ids)
    v.neighbors.push_back(ViewImage{v.sequence->View(j), v.sequence->RenderImage(j), cv::Mat(), cv::Mat()});
  v.foreground = synth::ForegroundMask(v.sequence->scene(), v.truth.labels);
  cv::dilate(v.truth.mixed, v.near_edge, cv::Mat::ones(5, 5, CV_8U));
  return v;
}

inline SynthViews MakeSynthViews(const std::string& scene, int reference = 0, double angle = 5.0,
                                 int width = 320, int height = 180, int frames = 480,
                                 synth::PathType path = synth::PathType::kCircle, double noise = -1) {
  synth::SynthOptions o;
  o.scene = scene;
  o.frames = frames;
  o.width = width;
  o.height = height;
  o.path = path;
  if (noise >= 0) o.render.noise_sigma = noise;
  return MakeSynthViewsOf(std::make_shared<synth::SynthSequence>(synth::SynthSequence::Create(o)), reference, angle);
}

// A scene built by the test: reference 0 of a 480-frame circle around
// `target`, its views within 5°, 320×180.
inline SynthViews MakeCustomViews(synth::Scene scene, const Eigen::Vector3d& target, double radius, double height) {
  synth::CameraPathOptions path;
  path.num_frames = 480;
  path.target = target;
  path.radius = radius;
  path.height = height;
  return MakeSynthViewsOf(std::make_shared<synth::SynthSequence>(
      std::move(scene), Camera::PinholeFromHfov(320, 180, 55.0), path, synth::RenderOptions(), 1));
}

struct Score {
  long long expected = 0, estimated = 0, accurate = 0;
  double Accuracy() const { return estimated ? double(accurate) / estimated : 0; }
  double Coverage() const { return expected ? double(estimated) / expected : 0; }
};

// Accuracy (within `tol` relative) and coverage over foreground pixels with
// ‖∇I‖ > g; `skip_edges` leaves out pixels within 2 px of occlusion edges.
inline Score ScoreDepth(const SynthViews& v, const DepthMap& m, bool skip_edges, double tol = 0.005,
                        double g = 0.05) {
  const cv::Mat grad = GradientMagnitude(v.ref.image);
  Score s;
  for (int r = 0; r < m.depth.rows; ++r)
    for (int c = 0; c < m.depth.cols; ++c) {
      if (!v.foreground.at<std::uint8_t>(r, c) || !(grad.at<float>(r, c) > g)) continue;
      if (skip_edges && v.near_edge.at<std::uint8_t>(r, c)) continue;
      const double t = v.truth.depth.at<double>(r, c);
      if (!(t > 0)) continue;
      ++s.expected;
      const float e = m.depth.at<float>(r, c);
      if (!(e > 0)) continue;
      ++s.estimated;
      s.accurate += std::abs(e - t) <= tol * t;
    }
  return s;
}

}  // namespace lfrecon::testing
