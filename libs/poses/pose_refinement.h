#pragma once
// Refines the given camera poses of a dense sequence against its own frames
// before depth estimation. A pose error of the size a good SfM solution has
// (0.02°, 0.5 mm per frame) moves a point 0.2-0.5 px between neighbouring
// frames: the same order as the sub-pixel shift the gradient depth (§3.1)
// measures, so neighbours 0.75° apart see it as a large depth error. Here
// corners are tracked through the sequence (pyramidal Lucas-Kanade, each step
// re-anchored to the frame the corner was found in, so tracks do not drift),
// triangulated with the given poses, and a bundle adjustment (Ceres) moves
// each frame's rotation and centre with a Gaussian prior around its given
// pose: per-frame errors are independent, so the prior is zero-mean and
// the many priors together fix the gauge (position, orientation, scale)
// to the given poses'. Intrinsics stay as given.
#include <cstdint>
#include <vector>

#include "geometry/pinhole_view.h"
#include "io/frame_source.h"

namespace lfrecon {

struct PoseRefinementOptions {
  // Corners tracked per frame (goodFeaturesToTrack), at least this far apart.
  int max_features = 800;
  double min_feature_distance_px = 7;
  double feature_quality = 0.003;
  int lk_window_px = 15;
  int lk_levels = 3;
  // A step is kept when tracking back lands within this of where it started.
  double max_forward_backward_px = 0.2;
  // The anchored refinement may move a chained position by at most this.
  double max_anchor_correction_px = 0.75;
  // Tracks end after this many frames (the anchor's patch must still look alike).
  int max_track_length = 10;
  int min_track_length = 4;
  // Triangulated with the given poses: observations farther than this from
  // the point's projection, and points seen under less than this angle, are left out.
  double max_initial_reprojection_px = 4.0;
  double min_triangulation_angle_deg = 1.0;
  // Robust loss scale of the reprojection error (Huber), pixels.
  double huber_px = 0.7;
  // σ of the prior around each given pose: rotation (degrees) and camera
  // centre (relative to the median distance of the tracked points from the
  // cameras, since SfM poses have no metric scale). Loose: a few times the
  // error of a good SfM solution (~0.02°, ~0.05 %).
  double prior_rotation_deg = 0.1;
  double prior_center_relative = 0.003;
  // The mean correction of every run of this many consecutive frames (half
  // overlapping) has the prior's σ/√W: per-frame errors are independent, a
  // drift is not (0 or 1: no such term).
  int local_mean_frames = 15;
  // After a first adjustment, observations farther than this many robust σ
  // (and than min_outlier_px) from their point are dropped and it is solved
  // again; 0: one round.
  double outlier_sigmas = 3.0;
  double min_outlier_px = 0.3;
  int max_iterations = 50;
  // Iterations of the first round when a second follows: it only has to tell
  // the outliers, and the second round starts where it stopped. 3 instead of
  // max_iterations (12 to converge) left the refined poses within 0.0001° /
  // 0.002 mm on four sets and took 4.5 s off the figurines' adjustment
  // (docs/benchmarks.md, "Pose refinement").
  int outlier_round_iterations = 3;
  int num_threads = 2;

  void Check() const;  // throws OptionError
};

struct PoseRefinementStats {
  int frames = 0;
  std::int64_t tracks = 0;        // triangulated tracks in the adjustment
  std::int64_t observations = 0;  // their observations
  std::int64_t outlier_observations = 0;  // dropped after the first round
  double rms_reprojection_before_px = 0;
  double rms_reprojection_after_px = 0;
  double median_reprojection_before_px = 0;
  double median_reprojection_after_px = 0;
  double median_rotation_change_deg = 0;
  double median_center_change = 0;  // world units
  double scene_distance = 0;        // median point-camera distance (world units)
  double seconds_tracking = 0;
  double seconds_solve = 0;
  bool converged = false;
};

struct PoseRefinementResult {
  std::vector<PinholeView> views;  // intrinsics as given, refined R and t
  PoseRefinementStats stats;
};

// Reads `frames` once, in order (frame k is views[k]). Frames too few or too
// untextured to track leave the poses as given (stats say so).
PoseRefinementResult RefinePoses(FrameSource& frames, const std::vector<PinholeView>& views,
                                 const PoseRefinementOptions& options);

// Rotation angle between two views' orientations, in degrees.
double RotationDifferenceDeg(const PinholeView& a, const PinholeView& b);

}  // namespace lfrecon
