// Pose error of a dataset's given poses against the true ones, before and
// after RefinePoses: absolute (per frame) and relative (between frames k and
// k+d, which is what the depth of neighbouring views sees).
//   pose_refinement_bench --dataset ../shared/data/figurines-noisy --truth ../shared/data/figurines
//   pose_refinement_bench --dataset GEN_DIR   (a `lfrecon synth --pose-rot-deg ...` set: truth from scene.json)
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <Eigen/Geometry>
#include <algorithm>
#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>

#include "io/dataset.h"
#include "poses/pose_refinement.h"
#include "util/error.h"
#include "util/memory.h"

using namespace lfrecon;

namespace {

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}
double Rms(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return v.empty() ? 0 : std::sqrt(s / v.size());
}

struct Errors {
  double rot_median_deg, rot_rms_deg, centre_median_mm, centre_rms_mm, rel_rot_rms_deg[3], rel_centre_rms_mm[3];
};

// Relative error of the pair (k, k+d): the error of view k+d expressed in view k's frame.
Errors Measure(const std::vector<PinholeView>& est, const std::vector<PinholeView>& truth, double unit_mm) {
  Errors e{};
  std::vector<double> rot, ctr;
  for (std::size_t i = 0; i < est.size(); ++i) {
    rot.push_back(RotationDifferenceDeg(est[i], truth[i]));
    ctr.push_back((est[i].Center() - truth[i].Center()).norm() * unit_mm);
  }
  e.rot_median_deg = Median(rot);
  e.rot_rms_deg = Rms(rot);
  e.centre_median_mm = Median(ctr);
  e.centre_rms_mm = Rms(ctr);
  const int gaps[3] = {1, 4, 16};
  for (int g = 0; g < 3; ++g) {
    std::vector<double> rr, rc;
    for (std::size_t i = 0; i + gaps[g] < est.size(); ++i) {
      const std::size_t j = i + static_cast<std::size_t>(gaps[g]);
      const Eigen::Matrix3d Re = est[j].R * est[i].R.transpose(), Rt = truth[j].R * truth[i].R.transpose();
      rr.push_back(Eigen::AngleAxisd(Re * Rt.transpose()).angle() * 180.0 / M_PI);
      const Eigen::Vector3d ce = est[i].R * (est[j].Center() - est[i].Center());
      const Eigen::Vector3d ct = truth[i].R * (truth[j].Center() - truth[i].Center());
      rc.push_back((ce - ct).norm() * unit_mm);
    }
    e.rel_rot_rms_deg[g] = Rms(rr);
    e.rel_centre_rms_mm[g] = Rms(rc);
  }
  return e;
}

void Print(const char* label, const Errors& e) {
  std::printf("%-8s rot median/RMS %.4f/%.4f deg  centre median/RMS %.3f/%.3f mm  relative RMS (gap 1,4,16): "
              "rot %.4f %.4f %.4f deg, centre %.3f %.3f %.3f mm\n",
              label, e.rot_median_deg, e.rot_rms_deg, e.centre_median_mm, e.centre_rms_mm, e.rel_rot_rms_deg[0],
              e.rel_rot_rms_deg[1], e.rel_rot_rms_deg[2], e.rel_centre_rms_mm[0], e.rel_centre_rms_mm[1],
              e.rel_centre_rms_mm[2]);
}

}  // namespace

int main(int argc, char** argv) {
  ConfigureHeap();
  CLI::App app("Pose error before and after pose refinement");
  std::string dataset, truth_dir;
  int frames = 0;
  PoseRefinementOptions o;
  app.add_option("--dataset", dataset, "Dataset with the given (noisy) poses")->required();
  app.add_option("--truth", truth_dir, "Dataset with the true poses (default: scene.json's true poses)");
  app.add_option("--frames", frames, "Use only the first N frames (0: all)");
  app.add_option("--max-features", o.max_features);
  app.add_option("--max-track-length", o.max_track_length);
  app.add_option("--huber-px", o.huber_px);
  app.add_option("--prior-rotation-deg", o.prior_rotation_deg);
  app.add_option("--prior-center-relative", o.prior_center_relative);
  app.add_option("--fb-px", o.max_forward_backward_px);
  app.add_option("--local-mean-frames", o.local_mean_frames);
  app.add_option("--outlier-sigmas", o.outlier_sigmas);
  app.add_option("--outlier-round-iterations", o.outlier_round_iterations);
  app.add_option("--max-iterations", o.max_iterations);
  app.add_option("--lk-levels", o.lk_levels);
  app.add_option("--lk-window", o.lk_window_px);
  bool verbose = false;
  app.add_flag("-v,--verbose", verbose, "Debug logging (the adjustment's full report)");
  CLI11_PARSE(app, argc, argv);
  if (verbose) spdlog::set_level(spdlog::level::debug);
  try {
    DatasetOptions d;
    d.dataset_dir = dataset;
    const Dataset ds = Dataset::Open(d);
    std::vector<PinholeView> given, truth;
    const int n = frames > 0 ? std::min(frames, ds.NumViews()) : ds.NumViews();
    for (int i = 0; i < n; ++i) given.push_back(ds.View(i));
    if (!truth_dir.empty()) {
      DatasetOptions t;
      t.dataset_dir = truth_dir;
      const Dataset tds = Dataset::Open(t);
      for (int i = 0; i < n; ++i) truth.push_back(tds.View(i));
    } else {
      std::ifstream f(std::filesystem::path(dataset) / "scene.json");
      const nlohmann::json j = nlohmann::json::parse(f);
      const auto& poses = j.at("true_cam_from_world_qwxyz_t");
      for (int i = 0; i < n; ++i) {
        const auto& p = poses.at(static_cast<std::size_t>(i));
        PinholeView v = given[static_cast<std::size_t>(i)];
        const Eigen::Quaterniond q(p[0].get<double>(), p[1].get<double>(), p[2].get<double>(), p[3].get<double>());
        v.R = q.normalized().toRotationMatrix();
        v.t = Eigen::Vector3d(p[4].get<double>(), p[5].get<double>(), p[6].get<double>());
        truth.push_back(v);
      }
    }
    class Prefix : public FrameSource {
     public:
      Prefix(std::unique_ptr<FrameSource> s, int n) : s_(std::move(s)), n_(n) {}
      int NumFrames() const override { return n_; }
      bool Next(Frame* f) override { return k_++ < n_ && s_->Next(f); }
      Frame Read(int i) override { return s_->Read(i); }

     private:
      std::unique_ptr<FrameSource> s_;
      int n_, k_ = 0;
    } source(ds.OpenFrames(), n);
    const PoseRefinementResult r = RefinePoses(source, given, o);
    const double unit_mm = 1000.0;  // metric datasets
    std::printf("%d frames, %lld tracks, %lld observations, reprojection RMS %.3f -> %.3f px, tracking %.1f s, "
                "adjustment %.1f s%s\n",
                n, static_cast<long long>(r.stats.tracks), static_cast<long long>(r.stats.observations),
                r.stats.rms_reprojection_before_px, r.stats.rms_reprojection_after_px, r.stats.seconds_tracking,
                r.stats.seconds_solve, r.stats.converged ? "" : " (not converged)");
    Print("given", Measure(given, truth, unit_mm));
    Print("refined", Measure(r.views, truth, unit_mm));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
