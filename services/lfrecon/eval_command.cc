// `lfrecon eval`: precision, recall and F-score of a reconstructed mesh against
// a dataset's ground truth (BRIEF §4), plus recall on the thin parts; recall
// and F both over all ground truth and over the part that some ground-truth
// depth map (depth/depth_NNNN.exr) observes.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "commands.h"
#include "dataset_flags.h"
#include "eval/mesh_metrics.h"
#include "io/dataset.h"
#include "io/depth_map_io.h"
#include "io/ply.h"
#include "util/error.h"
#include "util/progress.h"

namespace lfrecon::cli {
namespace {

struct EvalFlags {
  DatasetFlags dataset;
  std::string mesh;
  std::string gt;       // overrides the dataset's gt_mesh.ply
  std::string gt_thin;  // overrides the dataset's gt_thin.ply
  std::vector<double> thresholds_mm = {2, 5, 10};
  double spacing_mm = 1.0;
  std::uint64_t seed = 1;
  bool no_volume = false;
  bool no_observation = false;
  ObservationOptions observation;
  double observation_tolerance_mm = 2.0;
  bool json = false;
};

// The poses the ground-truth depth maps were rendered from, when scene.json
// keeps them apart from the given (perturbed) ones: `lfrecon synth
// --pose-rot-deg/--pose-trans-mm` writes true_cam_from_world_qwxyz_t. Empty
// when absent or not one per view.
std::vector<Rigid3d> TruePoses(const Dataset& ds) {
  std::vector<Rigid3d> poses;
  if (ds.root().empty()) return poses;
  const auto path = ds.root() / "scene.json";
  std::ifstream in(path);
  if (!in) return poses;
  const nlohmann::json j = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
  if (!j.is_object() || !j.contains("true_cam_from_world_qwxyz_t")) return poses;
  const nlohmann::json& a = j["true_cam_from_world_qwxyz_t"];
  if (!a.is_array() || static_cast<int>(a.size()) != ds.NumViews())
    throw InputError(path.string(), "true_cam_from_world_qwxyz_t", "needs one pose per view");
  for (const nlohmann::json& e : a) {
    if (!e.is_array() || e.size() != 7)
      throw InputError(path.string(), "true_cam_from_world_qwxyz_t", "each pose is [qw, qx, qy, qz, tx, ty, tz]");
    for (const nlohmann::json& v : e)
      if (!v.is_number())
        throw InputError(path.string(), "true_cam_from_world_qwxyz_t", "each pose is [qw, qx, qy, qz, tx, ty, tz]");
    Eigen::Quaterniond q(e[0].get<double>(), e[1].get<double>(), e[2].get<double>(), e[3].get<double>());
    if (!(q.norm() > 0.5)) throw InputError(path.string(), "true_cam_from_world_qwxyz_t", "quaternion is not unit");
    poses.emplace_back(q.normalized(), Eigen::Vector3d(e[4].get<double>(), e[5].get<double>(), e[6].get<double>()));
  }
  return poses;
}

// The dataset's views with a ground-truth depth map; each map is read when the mask needs it.
GroundTruthViews DepthMapViews(const Dataset& ds) {
  GroundTruthViews gt;
  auto paths = std::make_shared<std::vector<std::string>>();
  const std::vector<Rigid3d> true_poses = TruePoses(ds);
  for (int i = 0; i < ds.NumViews(); ++i) {
    const auto p = ds.GroundTruthDepthPath(i);
    if (!p) continue;
    gt.views.push_back(true_poses.empty() ? ds.View(i)
                                          : PinholeView(ds.UndistortedCamera(i), true_poses[static_cast<std::size_t>(i)]));
    paths->push_back(p->string());
  }
  if (!true_poses.empty() && !gt.views.empty())
    spdlog::info("observation mask: depth maps placed at scene.json's true poses (the given ones carry pose error)");
  const std::vector<PinholeView> views = gt.views;
  gt.load = [paths, views](int k) {
    const std::string& path = (*paths)[static_cast<std::size_t>(k)];
    cv::Mat d = ReadDepthMap(path);
    const PinholeView& v = views[static_cast<std::size_t>(k)];
    if (d.cols != v.width || d.rows != v.height)
      throw InputError(path, "depth map is " + std::to_string(d.cols) + "x" + std::to_string(d.rows) +
                                 " but its view is " + std::to_string(v.width) + "x" + std::to_string(v.height));
    return d;
  };
  return gt;
}

TriangleMesh ReadMesh(const std::string& path, const std::string& what) {
  TriangleMesh m = ReadPly(path);
  if (m.triangles.empty()) throw InputError(path, what + " has no faces (a point cloud cannot be evaluated)");
  return m;
}

int RunEval(const EvalFlags& flags) {
  if (flags.mesh.empty()) throw OptionError("eval: --mesh is required");
  if (flags.thresholds_mm.empty()) throw OptionError("eval: --thresholds-mm needs at least one value");
  for (double t : flags.thresholds_mm)
    if (!(t > 0)) throw OptionError("eval: --thresholds-mm values must be positive");
  if (!(flags.spacing_mm > 0)) throw OptionError("eval: --spacing-mm must be positive");
  const Dataset ds = Dataset::Open(flags.dataset.Resolve());
  std::string gt_path = flags.gt, thin_path = flags.gt_thin;
  if (gt_path.empty()) {
    const auto p = ds.GroundTruthMeshPath(false);
    if (!p) throw InputError(ds.root().string(), "no ground-truth mesh (gt_mesh.ply); pass --gt");
    gt_path = p->string();
  }
  if (thin_path.empty()) {
    if (const auto p = ds.GroundTruthMeshPath(true)) thin_path = p->string();
  }

  MeshMetricsOptions options;
  options.thresholds.clear();
  for (double t : flags.thresholds_mm) options.thresholds.push_back(t / 1000.0);
  options.sample_spacing = flags.spacing_mm / 1000.0;
  options.seed = flags.seed;
  if (!flags.no_volume) options.volume = ds.bbox();
  options.observation = flags.observation;
  options.observation.tolerance = flags.observation_tolerance_mm / 1000.0;
  options.Check();

  Timer timer;
  const TriangleMesh mesh = ReadMesh(flags.mesh, "the mesh");
  const TriangleMesh gt = ReadMesh(gt_path, "the ground-truth mesh");
  TriangleMesh thin;
  if (!thin_path.empty()) {
    thin = ReadPly(thin_path);
    if (thin.triangles.empty()) {  // a scene without thin parts: no thin recall
      spdlog::info("{} has no faces: no thin-part recall", thin_path);
      thin_path.clear();
    }
  }
  GroundTruthViews depth_views;
  if (!flags.no_observation) depth_views = DepthMapViews(ds);
  const bool masked = !depth_views.views.empty();
  if (!flags.no_observation && !masked)
    spdlog::info("{}: no ground-truth depth maps (depth/depth_NNNN.exr): only unmasked recall and F",
                 ds.root().string());
  const MeshMetrics m =
      EvaluateMesh(mesh, gt, thin_path.empty() ? nullptr : &thin, options, masked ? &depth_views : nullptr);
  const double seconds = timer.Seconds();
  const ObservationOptions& obs = options.observation;
  auto null_if_negative = [](double x) { return x < 0 ? nlohmann::json() : nlohmann::json(x); };

  const BoundingBox& b = ds.bbox();
  if (flags.json) {
    nlohmann::json j;
    j["mesh"] = flags.mesh;
    j["ground_truth"] = gt_path;
    j["ground_truth_thin"] = thin_path.empty() ? nlohmann::json() : nlohmann::json(thin_path);
    if (options.volume)
      j["volume"] = {{"min", {b.min.x(), b.min.y(), b.min.z()}},
                     {"max", {b.max.x(), b.max.y(), b.max.z()}},
                     {"source", ds.bbox_source()}};
    j["sample_spacing_mm"] = flags.spacing_mm;
    j["seed"] = flags.seed;
    j["samples"] = {{"reconstructed_in_volume", m.predicted_samples},
                    {"reconstructed_outside_volume", m.predicted_samples_outside},
                    {"ground_truth", m.gt_samples},
                    {"ground_truth_thin", m.thin_samples},
                    {"ground_truth_observed", masked ? nlohmann::json(m.gt_observed_samples) : nlohmann::json()},
                    {"ground_truth_thin_observed",
                     masked && !thin_path.empty() ? nlohmann::json(m.thin_observed_samples) : nlohmann::json()}};
    // Observation mask: null when the dataset has no ground-truth depth maps (or --no-observation).
    j["observed_share"] = masked ? nlohmann::json(m.ObservedShare()) : nlohmann::json();
    j["thin_observed_share"] = masked && !thin_path.empty() ? nlohmann::json(m.ThinObservedShare()) : nlohmann::json();
    if (masked)
      j["observation"] = {{"depth_maps", m.observation_views},
                          {"support_px", obs.support_px},
                          {"tolerance_mm", obs.tolerance * 1000.0},
                          {"relative_tolerance", obs.relative_tolerance}};
    else
      j["observation"] = nlohmann::json();
    j["area_m2"] = {{"reconstructed", m.predicted_area}, {"ground_truth", m.gt_area}};
    nlohmann::json scores = nlohmann::json::array();
    for (const ThresholdScore& s : m.scores) {
      nlohmann::json e = {{"threshold_mm", s.threshold * 1000.0},
                          {"precision", s.precision},
                          {"recall", s.recall},
                          {"fscore", s.fscore}};
      e["thin_recall"] = null_if_negative(s.thin_recall);
      e["recall_observed"] = null_if_negative(s.recall_observed);
      e["fscore_observed"] = null_if_negative(s.fscore_observed);
      e["thin_recall_observed"] = null_if_negative(s.thin_recall_observed);
      scores.push_back(e);
    }
    j["scores"] = scores;
    j["median_accuracy_mm"] = m.median_accuracy * 1000.0;
    j["median_completeness_mm"] = m.median_completeness * 1000.0;
    j["median_completeness_observed_mm"] =
        masked ? nlohmann::json(m.median_completeness_observed * 1000.0) : nlohmann::json();
    j["seconds"] = seconds;
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  std::printf("mesh          %s (%zu vertices, %zu triangles, %.4f m^2)\n", flags.mesh.c_str(), mesh.vertices.size(),
              mesh.triangles.size(), m.predicted_area);
  std::printf("ground truth  %s (%.4f m^2)%s%s\n", gt_path.c_str(), m.gt_area, thin_path.empty() ? "" : ", thin ",
              thin_path.c_str());
  if (options.volume)
    std::printf("V             [%g %g %g] .. [%g %g %g] m (from %s); %zu of %zu reconstructed samples outside V ignored\n",
                b.min.x(), b.min.y(), b.min.z(), b.max.x(), b.max.y(), b.max.z(), ds.bbox_source().c_str(),
                m.predicted_samples_outside, m.predicted_samples + m.predicted_samples_outside);
  std::printf("samples       %zu reconstructed, %zu ground truth, %zu thin (one per %.2f mm^2, seed %llu)\n",
              m.predicted_samples, m.gt_samples, m.thin_samples, flags.spacing_mm * flags.spacing_mm,
              static_cast<unsigned long long>(flags.seed));
  if (masked) {
    std::printf("observed      %zu of %zu ground-truth samples (%.1f %%)", m.gt_observed_samples, m.gt_samples,
                100.0 * m.ObservedShare());
    if (!thin_path.empty())
      std::printf(", %zu of %zu thin (%.1f %%)", m.thin_observed_samples, m.thin_samples,
                  100.0 * m.ThinObservedShare());
    std::printf(" seen by %d ground-truth depth maps (%dx%d px support, tolerance max(%g mm, %g %% of depth))\n",
                m.observation_views, obs.support_px, obs.support_px, obs.tolerance * 1000,
                obs.relative_tolerance * 100);
  } else if (flags.no_observation) {
    std::printf("observed      not computed (--no-observation): recall and F count all ground truth\n");
  } else {
    std::printf("observed      no ground-truth depth maps (depth/depth_NNNN.exr): recall and F count all ground "
                "truth, seen or not\n");
  }
  auto cell = [](double x) {  // "-" for a figure that does not apply (-1)
    char b[32] = "-";
    if (x >= 0) std::snprintf(b, sizeof(b), "%.4f", x);
    return std::string(b);
  };
  if (masked)
    std::printf("%8s %10s %8s %8s %12s | %12s %9s %10s\n", "tau(mm)", "precision", "recall", "F-score",
                "thin recall", "recall(obs)", "F(obs)", "thin(obs)");
  else
    std::printf("%8s %10s %8s %8s %12s\n", "tau(mm)", "precision", "recall", "F-score", "thin recall");
  for (const ThresholdScore& s : m.scores) {
    std::printf("%8g %10.4f %8.4f %8.4f %12s", s.threshold * 1000, s.precision, s.recall, s.fscore,
                cell(s.thin_recall).c_str());
    if (masked)
      std::printf(" | %12.4f %9.4f %10s", s.recall_observed, s.fscore_observed, cell(s.thin_recall_observed).c_str());
    std::printf("\n");
  }
  std::printf("median distance: reconstruction->truth %.3f mm, truth->reconstruction %.3f mm", m.median_accuracy * 1000,
              m.median_completeness * 1000);
  if (masked) std::printf(" (observed truth %.3f mm)", m.median_completeness_observed * 1000);
  std::printf(" (capped at %g mm)\n", *std::max_element(flags.thresholds_mm.begin(), flags.thresholds_mm.end()));
  spdlog::info("eval took {:.1f} s", seconds);
  return 0;
}

}  // namespace

void AddEvalCommand(CLI::App& root, int* exit_code) {
  auto* cmd = root.add_subcommand(
      "eval", "Precision, recall and F-score of a mesh against the dataset's ground truth (and thin-part recall)");
  auto flags = std::make_shared<EvalFlags>();
  flags->dataset.AddTo(cmd);
  cmd->add_option("--mesh", flags->mesh, "Reconstructed mesh (PLY)")->required();
  cmd->add_option("--gt", flags->gt, "Ground-truth mesh (default: the dataset's gt_mesh.ply)");
  cmd->add_option("--gt-thin", flags->gt_thin, "Thin-part ground truth (default: the dataset's gt_thin.ply)");
  cmd->add_option("--thresholds-mm", flags->thresholds_mm, "Distance thresholds tau in mm (default 2 5 10)")
      ->delimiter(',');
  cmd->add_option("--spacing-mm", flags->spacing_mm, "One surface sample per spacing^2 of area (default 1 mm)");
  cmd->add_option("--seed", flags->seed, "Sampling seed (default 1)");
  cmd->add_flag("--no-volume", flags->no_volume, "Do not restrict the reconstruction's samples to V");
  cmd->add_flag("--no-observation", flags->no_observation,
                "Do not mask the ground truth by what the ground-truth depth maps observe (unmasked figures only)");
  cmd->add_option("--observation-support-px", flags->observation.support_px,
                  "Observation mask: a ground-truth point is seen when its depth is at most the largest depth of the "
                  "N x N pixels around its projection plus the tolerance")
      ->capture_default_str();
  cmd->add_option("--observation-tolerance-mm", flags->observation_tolerance_mm,
                  "Observation mask: absolute depth tolerance in mm")
      ->capture_default_str();
  cmd->add_option("--observation-relative-tolerance", flags->observation.relative_tolerance,
                  "Observation mask: depth tolerance as a share of the depth (the larger of the two applies)")
      ->capture_default_str();
  cmd->add_flag("--json", flags->json, "Print the result as JSON on stdout");
  cmd->callback([flags, exit_code] { *exit_code = RunEval(*flags); });
}

}  // namespace lfrecon::cli
