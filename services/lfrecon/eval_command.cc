// `lfrecon eval`: precision, recall and F-score of a reconstructed mesh against
// a dataset's ground truth (BRIEF §4), plus recall on the thin parts.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstdio>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "commands.h"
#include "dataset_flags.h"
#include "eval/mesh_metrics.h"
#include "io/dataset.h"
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
  bool json = false;
};

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
  const MeshMetrics m = EvaluateMesh(mesh, gt, thin_path.empty() ? nullptr : &thin, options);
  const double seconds = timer.Seconds();

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
                    {"ground_truth_thin", m.thin_samples}};
    j["area_m2"] = {{"reconstructed", m.predicted_area}, {"ground_truth", m.gt_area}};
    nlohmann::json scores = nlohmann::json::array();
    for (const ThresholdScore& s : m.scores) {
      nlohmann::json e = {{"threshold_mm", s.threshold * 1000.0},
                          {"precision", s.precision},
                          {"recall", s.recall},
                          {"fscore", s.fscore}};
      e["thin_recall"] = s.thin_recall < 0 ? nlohmann::json() : nlohmann::json(s.thin_recall);
      scores.push_back(e);
    }
    j["scores"] = scores;
    j["median_accuracy_mm"] = m.median_accuracy * 1000.0;
    j["median_completeness_mm"] = m.median_completeness * 1000.0;
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
  std::printf("%8s %10s %8s %8s %12s\n", "tau(mm)", "precision", "recall", "F-score", "thin recall");
  for (const ThresholdScore& s : m.scores) {
    if (s.thin_recall < 0)
      std::printf("%8g %10.4f %8.4f %8.4f %12s\n", s.threshold * 1000, s.precision, s.recall, s.fscore, "-");
    else
      std::printf("%8g %10.4f %8.4f %8.4f %12.4f\n", s.threshold * 1000, s.precision, s.recall, s.fscore,
                  s.thin_recall);
  }
  std::printf("median distance: reconstruction->truth %.3f mm, truth->reconstruction %.3f mm (capped at %g mm)\n",
              m.median_accuracy * 1000, m.median_completeness * 1000,
              *std::max_element(flags.thresholds_mm.begin(), flags.thresholds_mm.end()));
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
  cmd->add_flag("--json", flags->json, "Print the result as JSON on stdout");
  cmd->callback([flags, exit_code] { *exit_code = RunEval(*flags); });
}

}  // namespace lfrecon::cli
