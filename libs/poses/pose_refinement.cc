#include "poses/pose_refinement.h"

#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <deque>
#include <map>
#include <opencv2/imgproc.hpp>
#include <opencv2/video/tracking.hpp>

#include "util/error.h"
#include "util/progress.h"

namespace lfrecon {
namespace {

struct Observation {
  int frame;
  Eigen::Vector2d pixel;  // COLMAP convention (pixel centre at +0.5)
};

struct Track {
  int anchor = 0;             // frame the corner was found in
  cv::Point2f anchor_point;   // its position there (OpenCV convention)
  cv::Point2f last;           // its position in the latest frame (OpenCV convention)
  std::vector<Observation> obs;
};

cv::Mat Grey8(const cv::Mat& bgr) {
  cv::Mat grey;
  if (bgr.channels() == 3)
    cv::cvtColor(bgr, grey, cv::COLOR_BGR2GRAY);
  else
    grey = bgr;
  cv::Mat out;
  if (grey.depth() == CV_8U)
    out = grey.clone();
  else
    grey.convertTo(out, CV_8U, grey.depth() == CV_16U ? 1.0 / 257.0 : 255.0);
  return out;
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  const std::size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  return v[mid];
}

// Linear (DLT) triangulation in normalised coordinates.
bool Triangulate(const std::vector<Observation>& obs, const std::vector<PinholeView>& views, Eigen::Vector3d* X) {
  Eigen::MatrixXd A(2 * obs.size(), 4);
  for (std::size_t k = 0; k < obs.size(); ++k) {
    const PinholeView& v = views[static_cast<std::size_t>(obs[k].frame)];
    const Eigen::Vector3d n = v.K_inv * obs[k].pixel.homogeneous();
    Eigen::Matrix<double, 3, 4> P;
    P << v.R, v.t;
    A.row(2 * k) = n.x() / n.z() * P.row(2) - P.row(0);
    A.row(2 * k + 1) = n.y() / n.z() * P.row(2) - P.row(1);
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(A, Eigen::ComputeFullV);
  const Eigen::Vector4d h = svd.matrixV().col(3);
  if (std::abs(h.w()) < 1e-12) return false;
  *X = h.head<3>() / h.w();
  return X->allFinite();
}

// Reprojection of point X in a view whose rotation and centre are corrected by
// delta = [ω (angle-axis, applied in the camera frame), δc]: R' = exp(ω) R0, c' = c0 + δc.
struct ReprojectionCost {
  ReprojectionCost(const PinholeView& v, const Eigen::Vector2d& observed) : observed_(observed) {
    for (int i = 0; i < 9; ++i) R0_[i] = v.R(i / 3, i % 3);
    const Eigen::Vector3d c = v.Center();
    for (int i = 0; i < 3; ++i) c0_[i] = c[i];
    fx_ = v.K(0, 0);
    fy_ = v.K(1, 1);
    cx_ = v.K(0, 2);
    cy_ = v.K(1, 2);
    skew_ = v.K(0, 1);
  }
  template <typename T>
  bool operator()(const T* delta, const T* X, T* residual) const {
    T d[3], y[3], x[3];
    for (int i = 0; i < 3; ++i) d[i] = X[i] - T(c0_[i]) - delta[3 + i];
    for (int i = 0; i < 3; ++i) y[i] = T(R0_[3 * i]) * d[0] + T(R0_[3 * i + 1]) * d[1] + T(R0_[3 * i + 2]) * d[2];
    ceres::AngleAxisRotatePoint(delta, y, x);
    if (x[2] <= T(1e-9)) {
      residual[0] = residual[1] = T(0);
      return true;  // behind the camera: no gradient rather than a NaN
    }
    const T u = x[0] / x[2], v = x[1] / x[2];
    residual[0] = T(fx_) * u + T(skew_) * v + T(cx_) - T(observed_.x());
    residual[1] = T(fy_) * v + T(cy_) - T(observed_.y());
    return true;
  }
  Eigen::Vector2d observed_;
  double R0_[9], c0_[3], fx_, fy_, cx_, cy_, skew_;
};

struct PosePriorCost {
  PosePriorCost(double inv_sigma_rotation, double inv_sigma_center)
      : inv_r_(inv_sigma_rotation), inv_c_(inv_sigma_center) {}
  template <typename T>
  bool operator()(const T* delta, T* residual) const {
    for (int i = 0; i < 3; ++i) residual[i] = T(inv_r_) * delta[i];
    for (int i = 0; i < 3; ++i) residual[3 + i] = T(inv_c_) * delta[3 + i];
    return true;
  }
  double inv_r_, inv_c_;
};

// The mean correction of a run of consecutive frames, scaled by 1/σ: the given
// poses' errors are independent per frame, so their local mean is near zero,
// while what short tracks cannot see (a slow drift, a bend of the whole path)
// shows as a local mean. Linear, so its Jacobian is written out.
class LocalMeanPriorCost : public ceres::CostFunction {
 public:
  LocalMeanPriorCost(int frames, double inv_sigma_rotation, double inv_sigma_center) : n_(frames) {
    for (int i = 0; i < 3; ++i) w_[i] = inv_sigma_rotation / frames;
    for (int i = 3; i < 6; ++i) w_[i] = inv_sigma_center / frames;
    set_num_residuals(6);
    for (int k = 0; k < frames; ++k) mutable_parameter_block_sizes()->push_back(6);
  }
  bool Evaluate(double const* const* params, double* residuals, double** jacobians) const override {
    for (int i = 0; i < 6; ++i) {
      double sum = 0;
      for (int k = 0; k < n_; ++k) sum += params[k][i];
      residuals[i] = w_[i] * sum;
    }
    if (jacobians)
      for (int k = 0; k < n_; ++k) {
        if (!jacobians[k]) continue;
        for (int r = 0; r < 6; ++r)
          for (int c = 0; c < 6; ++c) jacobians[k][6 * r + c] = r == c ? w_[r] : 0.0;
      }
    return true;
  }

 private:
  int n_;
  double w_[6];
};

PinholeView Corrected(const PinholeView& v, const double* delta) {
  PinholeView out = v;
  const Eigen::Vector3d w(delta[0], delta[1], delta[2]);
  const Eigen::Matrix3d dR =
      w.norm() > 0 ? Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix() : Eigen::Matrix3d::Identity();
  const Eigen::Vector3d c = v.Center() + Eigen::Vector3d(delta[3], delta[4], delta[5]);
  out.R = dR * v.R;
  // Re-orthonormalise (the product of two rotations drifts by rounding only).
  const Eigen::Quaterniond q(out.R);
  out.R = q.normalized().toRotationMatrix();
  out.t = -out.R * c;
  return out;
}

double ReprojectionError(const PinholeView& v, const Eigen::Vector3d& X, const Eigen::Vector2d& obs) {
  Eigen::Vector2d p;
  if (v.Project(X, &p) <= 0) return std::numeric_limits<double>::infinity();
  return (p - obs).norm();
}

}  // namespace

void PoseRefinementOptions::Check() const {
  LFRECON_CHECK_OPTION(max_features >= 8 && max_features <= 100000);
  LFRECON_CHECK_OPTION(std::isfinite(min_feature_distance_px) && min_feature_distance_px >= 1);
  LFRECON_CHECK_OPTION(std::isfinite(feature_quality) && feature_quality > 0 && feature_quality < 1);
  LFRECON_CHECK_OPTION(lk_window_px >= 5 && lk_window_px <= 101);
  LFRECON_CHECK_OPTION(lk_levels >= 0 && lk_levels <= 8);
  LFRECON_CHECK_OPTION(std::isfinite(max_forward_backward_px) && max_forward_backward_px > 0);
  LFRECON_CHECK_OPTION(std::isfinite(max_anchor_correction_px) && max_anchor_correction_px > 0);
  LFRECON_CHECK_OPTION(max_track_length >= 2 && max_track_length <= 10000);
  LFRECON_CHECK_OPTION(min_track_length >= 2 && min_track_length <= max_track_length);
  LFRECON_CHECK_OPTION(std::isfinite(max_initial_reprojection_px) && max_initial_reprojection_px > 0);
  LFRECON_CHECK_OPTION(std::isfinite(min_triangulation_angle_deg) && min_triangulation_angle_deg >= 0);
  LFRECON_CHECK_OPTION(std::isfinite(huber_px) && huber_px > 0);
  LFRECON_CHECK_OPTION(std::isfinite(prior_rotation_deg) && prior_rotation_deg > 0);
  LFRECON_CHECK_OPTION(std::isfinite(prior_center_relative) && prior_center_relative > 0);
  LFRECON_CHECK_OPTION(local_mean_frames >= 0 && local_mean_frames <= 1000);
  LFRECON_CHECK_OPTION(std::isfinite(outlier_sigmas) && outlier_sigmas >= 0);
  LFRECON_CHECK_OPTION(std::isfinite(min_outlier_px) && min_outlier_px > 0);
  LFRECON_CHECK_OPTION(max_iterations >= 1 && max_iterations <= 1000);
  LFRECON_CHECK_OPTION(outlier_round_iterations >= 1 && outlier_round_iterations <= 1000);
  LFRECON_CHECK_OPTION(num_threads >= 1 && num_threads <= 256);
}

double RotationDifferenceDeg(const PinholeView& a, const PinholeView& b) {
  return Eigen::AngleAxisd(a.R * b.R.transpose()).angle() * 180.0 / M_PI;
}

PoseRefinementResult RefinePoses(FrameSource& frames, const std::vector<PinholeView>& views,
                                 const PoseRefinementOptions& options) {
  options.Check();
  PoseRefinementResult result;
  result.views = views;
  PoseRefinementStats& st = result.stats;
  const int n = static_cast<int>(views.size());
  st.frames = n;
  if (n < 3) return result;

  // 1. Tracks.
  Timer timer;
  std::vector<Track> finished, active;
  // Each frame's LK pyramid with its Scharr derivatives is built once and
  // serves every call it takes part in (forward, backward, and as the anchor
  // of later re-anchoring): calcOpticalFlowPyrLK given plain images rebuilds
  // both pyramids and the first image's derivatives on every call, ten or
  // more times per frame here. Same arguments and borders as it uses, so the
  // tracks are bit-identical.
  using Pyramid = std::vector<cv::Mat>;
  std::deque<std::pair<int, Pyramid>> recent;  // pyramids of the frames that anchor live tracks
  const cv::Size win(options.lk_window_px, options.lk_window_px);
  const cv::TermCriteria crit(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 30, 0.005);
  Pyramid prev;
  Frame frame;
  int k = 0;
  Progress progress("pose refinement: tracking", n);
  auto finish = [&](Track&& t) {
    if (static_cast<int>(t.obs.size()) >= options.min_track_length) finished.push_back(std::move(t));
  };
  while (frames.Next(&frame)) {
    if (frame.index != k)
      throw InputError(frame.name, "pose refinement reads frames in order; expected frame " + std::to_string(k));
    if (k >= n) throw InputError(frame.name, "more frames than cameras");
    const cv::Mat grey = Grey8(frame.image);
    Pyramid pyramid;
    cv::buildOpticalFlowPyramid(grey, pyramid, win, options.lk_levels, true);
    if (!active.empty()) {
      std::vector<cv::Point2f> p0, p1, pb;
      for (const Track& t : active) p0.push_back(t.last);
      std::vector<uchar> s1, s2;
      std::vector<float> err;
      cv::calcOpticalFlowPyrLK(prev, pyramid, p0, p1, s1, err, win, options.lk_levels, crit);
      cv::calcOpticalFlowPyrLK(pyramid, prev, p1, pb, s2, err, win, options.lk_levels, crit);
      // Re-anchor: each survivor is tracked again from its anchor frame's
      // patch, starting from the chained position, so steps do not add up.
      std::map<int, std::vector<int>> by_anchor;
      const float margin = 0.5f * options.lk_window_px;
      for (std::size_t i = 0; i < active.size(); ++i) {
        const bool inside = p1[i].x >= margin && p1[i].y >= margin && p1[i].x < grey.cols - margin &&
                            p1[i].y < grey.rows - margin;
        if (s1[i] && s2[i] && inside && cv::norm(pb[i] - p0[i]) <= options.max_forward_backward_px)
          by_anchor[active[i].anchor].push_back(static_cast<int>(i));
      }
      std::vector<char> keep(active.size(), 0);
      for (auto& [anchor, ids] : by_anchor) {
        const auto it = std::find_if(recent.begin(), recent.end(), [&](const auto& r) { return r.first == anchor; });
        if (it == recent.end()) continue;
        std::vector<cv::Point2f> a0, a1;
        for (int i : ids) {
          a0.push_back(active[static_cast<std::size_t>(i)].anchor_point);
          a1.push_back(p1[static_cast<std::size_t>(i)]);
        }
        std::vector<uchar> s3;
        cv::calcOpticalFlowPyrLK(it->second, pyramid, a0, a1, s3, err, win, 0, crit, cv::OPTFLOW_USE_INITIAL_FLOW);
        for (std::size_t m = 0; m < ids.size(); ++m) {
          const std::size_t i = static_cast<std::size_t>(ids[m]);
          if (!s3[m] || cv::norm(a1[m] - p1[i]) > options.max_anchor_correction_px) continue;
          keep[i] = 1;
          p1[i] = a1[m];
        }
      }
      std::vector<Track> next;
      for (std::size_t i = 0; i < active.size(); ++i) {
        Track& t = active[i];
        if (!keep[i]) {
          finish(std::move(t));
          continue;
        }
        t.last = p1[i];
        t.obs.push_back({k, Eigen::Vector2d(p1[i].x + 0.5, p1[i].y + 0.5)});
        if (static_cast<int>(t.obs.size()) >= options.max_track_length)
          finish(std::move(t));
        else
          next.push_back(std::move(t));
      }
      active.swap(next);
    }
    if (static_cast<int>(active.size()) < options.max_features) {
      cv::Mat mask(grey.size(), CV_8U, cv::Scalar(255));
      for (const Track& t : active)
        cv::circle(mask, t.last, static_cast<int>(std::ceil(options.min_feature_distance_px)), cv::Scalar(0), -1);
      std::vector<cv::Point2f> corners;
      cv::goodFeaturesToTrack(grey, corners, options.max_features - static_cast<int>(active.size()),
                              options.feature_quality, options.min_feature_distance_px, mask, 5);
      if (!corners.empty()) {
        cv::cornerSubPix(grey, corners, cv::Size(3, 3), cv::Size(-1, -1),
                         cv::TermCriteria(cv::TermCriteria::COUNT | cv::TermCriteria::EPS, 20, 0.01));
        for (const cv::Point2f& c : corners) {
          Track t;
          t.anchor = k;
          t.anchor_point = c;
          t.last = c;
          t.obs.push_back({k, Eigen::Vector2d(c.x + 0.5, c.y + 0.5)});
          active.push_back(std::move(t));
        }
      }
    }
    recent.emplace_back(k, pyramid);
    int oldest = k;
    for (const Track& t : active) oldest = std::min(oldest, t.anchor);
    while (!recent.empty() && recent.front().first < oldest) recent.pop_front();
    prev = std::move(pyramid);
    ++k;
    progress.Advance();
  }
  progress.Finish();
  for (Track& t : active) finish(std::move(t));
  active.clear();
  recent.clear();
  if (k != n) throw InputError("frames", "pose refinement: " + std::to_string(k) + " frames for " +
                                             std::to_string(n) + " cameras");
  st.seconds_tracking = timer.Seconds();

  // 2. Points from the given poses; observations that disagree are left out.
  struct Point {
    Eigen::Vector3d X;
    std::vector<Observation> obs;
  };
  std::vector<Point> points;
  std::vector<double> distances;
  double sq_before = 0;
  std::int64_t count_before = 0;
  std::vector<double> err_before;
  for (const Track& t : finished) {
    Point p;
    if (!Triangulate(t.obs, views, &p.X)) continue;
    for (const Observation& o : t.obs)
      if (ReprojectionError(views[static_cast<std::size_t>(o.frame)], p.X, o.pixel) <=
          options.max_initial_reprojection_px)
        p.obs.push_back(o);
    if (static_cast<int>(p.obs.size()) < options.min_track_length) continue;
    const PinholeView& first = views[static_cast<std::size_t>(p.obs.front().frame)];
    const PinholeView& last = views[static_cast<std::size_t>(p.obs.back().frame)];
    const Eigen::Vector3d r1 = (p.X - first.Center()).normalized(), r2 = (p.X - last.Center()).normalized();
    if (AngleBetweenDeg(r1, r2) < options.min_triangulation_angle_deg) continue;
    for (const Observation& o : p.obs) {
      const double e = ReprojectionError(views[static_cast<std::size_t>(o.frame)], p.X, o.pixel);
      sq_before += e * e;
      ++count_before;
      err_before.push_back(e);
    }
    distances.push_back((p.X - first.Center()).norm());
    points.push_back(std::move(p));
  }
  finished.clear();
  st.tracks = static_cast<std::int64_t>(points.size());
  st.observations = count_before;
  st.rms_reprojection_before_px = count_before > 0 ? std::sqrt(sq_before / count_before) : 0;
  st.median_reprojection_before_px = Median(err_before);
  if (points.size() < 20) {
    spdlog::warn("pose refinement: only {} usable tracks in {} frames; poses kept as given", points.size(), n);
    return result;
  }
  st.scene_distance = Median(distances);

  // Frames that no point sees are left as given (their block stays constant).
  std::vector<int> seen(static_cast<std::size_t>(n), 0);
  for (const Point& p : points)
    for (const Observation& o : p.obs) ++seen[static_cast<std::size_t>(o.frame)];

  // 3. Bundle adjustment of the frames' corrections and the points.
  timer = Timer();
  std::vector<std::array<double, 6>> delta(static_cast<std::size_t>(n), std::array<double, 6>{0, 0, 0, 0, 0, 0});
  ceres::Problem::Options problem_options;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  problem_options.enable_fast_removal = true;
  ceres::Problem problem(problem_options);
  ceres::HuberLoss huber(options.huber_px);
  struct Residual {
    ceres::ResidualBlockId id;
    int point, obs;
  };
  std::vector<Residual> residuals;
  for (std::size_t pi = 0; pi < points.size(); ++pi) {
    Point& p = points[pi];
    for (std::size_t oi = 0; oi < p.obs.size(); ++oi) {
      const Observation& o = p.obs[oi];
      auto* cost = new ceres::AutoDiffCostFunction<ReprojectionCost, 2, 6, 3>(
          new ReprojectionCost(views[static_cast<std::size_t>(o.frame)], o.pixel));
      residuals.push_back({problem.AddResidualBlock(cost, &huber, delta[static_cast<std::size_t>(o.frame)].data(),
                                                    p.X.data()),
                           static_cast<int>(pi), static_cast<int>(oi)});
    }
  }
  const double inv_r = 1.0 / (options.prior_rotation_deg * M_PI / 180.0);
  const double inv_c = 1.0 / (options.prior_center_relative * st.scene_distance);
  for (int f = 0; f < n; ++f) {
    if (!seen[static_cast<std::size_t>(f)]) continue;
    problem.AddResidualBlock(new ceres::AutoDiffCostFunction<PosePriorCost, 6, 6>(new PosePriorCost(inv_r, inv_c)),
                             nullptr, delta[static_cast<std::size_t>(f)].data());
  }
  // Local means over runs of W seen frames: σ/√W each, as W independent errors of σ would give.
  const int W = std::min(options.local_mean_frames, n);
  if (W >= 2) {
    std::vector<int> seen_frames;
    for (int f = 0; f < n; ++f)
      if (seen[static_cast<std::size_t>(f)]) seen_frames.push_back(f);
    const double root_w = std::sqrt(static_cast<double>(W));
    for (std::size_t a = 0; a + static_cast<std::size_t>(W) <= seen_frames.size();
         a += static_cast<std::size_t>(std::max(1, W / 2))) {
      std::vector<double*> blocks;
      for (int k = 0; k < W; ++k) blocks.push_back(delta[static_cast<std::size_t>(seen_frames[a + k])].data());
      problem.AddResidualBlock(new LocalMeanPriorCost(W, inv_r * root_w, inv_c * root_w), nullptr, blocks);
    }
  }
  ceres::Solver::Options solver;
  solver.linear_solver_type =
      ceres::IsSparseLinearAlgebraLibraryTypeAvailable(ceres::SUITE_SPARSE) ? ceres::SPARSE_SCHUR
                                                                            : ceres::ITERATIVE_SCHUR;
  if (solver.linear_solver_type == ceres::ITERATIVE_SCHUR) solver.preconditioner_type = ceres::SCHUR_JACOBI;
  solver.max_num_iterations = options.max_iterations;
  solver.num_threads = options.num_threads;
  solver.logging_type = ceres::SILENT;
  solver.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  if (options.outlier_sigmas > 0) solver.max_num_iterations = options.outlier_round_iterations;
  ceres::Solve(solver, &problem, &summary);
  solver.max_num_iterations = options.max_iterations;
  spdlog::debug("pose refinement, first round: {}", summary.FullReport());
  if (summary.IsSolutionUsable() && options.outlier_sigmas > 0) {
    // Second round without the observations the first one could not explain
    // (corners on occlusion edges, which are no fixed point): beyond
    // outlier_sigmas robust standard deviations (1.4826 MAD) of all errors.
    std::vector<double> err(residuals.size());
    for (std::size_t r = 0; r < residuals.size(); ++r) {
      const Residual& res = residuals[r];
      const Observation& o = points[static_cast<std::size_t>(res.point)].obs[static_cast<std::size_t>(res.obs)];
      const PinholeView v = Corrected(views[static_cast<std::size_t>(o.frame)],
                                      delta[static_cast<std::size_t>(o.frame)].data());
      err[r] = ReprojectionError(v, points[static_cast<std::size_t>(res.point)].X, o.pixel);
    }
    const double limit = std::max(options.min_outlier_px, options.outlier_sigmas * 1.4826 * Median(err));
    std::int64_t removed = 0;
    for (std::size_t r = 0; r < residuals.size(); ++r)
      if (!(err[r] <= limit)) {
        problem.RemoveResidualBlock(residuals[r].id);
        ++removed;
      }
    st.outlier_observations = removed;
    ceres::Solve(solver, &problem, &summary);
  }
  spdlog::debug("pose refinement: {}", summary.FullReport());
  st.converged = summary.termination_type == ceres::CONVERGENCE;
  st.seconds_solve = timer.Seconds();
  if (!summary.IsSolutionUsable()) {
    spdlog::warn("pose refinement: the adjustment failed ({}); poses kept as given", summary.message);
    return result;
  }

  std::vector<double> rot_change, centre_change;
  for (int f = 0; f < n; ++f) {
    const std::size_t i = static_cast<std::size_t>(f);
    result.views[i] = Corrected(views[i], delta[i].data());
    rot_change.push_back(RotationDifferenceDeg(result.views[i], views[i]));
    centre_change.push_back((result.views[i].Center() - views[i].Center()).norm());
  }
  double sq_after = 0;
  std::int64_t count_after = 0;
  std::vector<double> err_after;
  for (const Point& p : points)
    for (const Observation& o : p.obs) {
      const double e = ReprojectionError(result.views[static_cast<std::size_t>(o.frame)], p.X, o.pixel);
      if (!std::isfinite(e)) continue;
      sq_after += e * e;
      ++count_after;
      err_after.push_back(e);
    }
  st.rms_reprojection_after_px = count_after > 0 ? std::sqrt(sq_after / count_after) : 0;
  st.median_reprojection_after_px = Median(err_after);
  st.median_rotation_change_deg = Median(rot_change);
  st.median_center_change = Median(centre_change);
  spdlog::info(
      "pose refinement: {} frames, {} tracks, {} observations; reprojection RMS {:.3f} -> {:.3f} px (median "
      "{:.3f} -> {:.3f}); median "
      "change {:.4f} deg, {:.3g} (scene distance {:.3g}); tracking {:.1f} s, adjustment {:.1f} s ({} iterations{})",
      n, st.tracks, st.observations, st.rms_reprojection_before_px, st.rms_reprojection_after_px,
      st.median_reprojection_before_px, st.median_reprojection_after_px, st.median_rotation_change_deg, st.median_center_change, st.scene_distance, st.seconds_tracking,
      st.seconds_solve, summary.iterations.size(), st.converged ? "" : ", not converged");
  return result;
}

}  // namespace lfrecon
