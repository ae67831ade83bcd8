// `lfrecon info`: a summary of a dataset (views, cameras, V, neighbourhoods,
// ground truth), the first thing to check before a reconstruction.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "commands.h"
#include "dataset_flags.h"
#include "geometry/view_graph.h"
#include "io/dataset.h"

namespace lfrecon::cli {
namespace {

struct NeighbourStats {
  double mean = 0;
  int min = 0;
  int max = 0;
  int isolated = 0;  // views with no neighbour
};

NeighbourStats Stats(const ViewGraph& g) {
  NeighbourStats s;
  if (g.num_views() == 0) return s;
  s.min = 1 << 30;
  for (int i = 0; i < g.num_views(); ++i) {
    const int n = static_cast<int>(g.Neighbors(i).size());
    s.mean += n;
    s.min = std::min(s.min, n);
    s.max = std::max(s.max, n);
    if (n == 0) ++s.isolated;
  }
  s.mean /= g.num_views();
  return s;
}

int RunInfo(const DatasetFlags& flags, bool as_json) {
  const Dataset ds = Dataset::Open(flags.Resolve());
  nlohmann::json j;
  j["dataset"] = ds.root().string();
  j["views"] = ds.NumViews();
  j["pose_source"] = ds.pose_source();
  std::map<std::string, int> cameras;
  std::vector<Eigen::Vector3d> dirs;
  double step_sum = 0;
  for (int i = 0; i < ds.NumViews(); ++i) {
    const Camera& c = ds.views()[i].camera;
    std::string key = CameraModelName(c.model) + " " + std::to_string(c.width) + "x" + std::to_string(c.height);
    cameras[key]++;
    dirs.push_back(ViewingDirection(ds.views()[i].cam_from_world));
    if (i > 0) step_sum += ViewAngleDeg(ds.views()[i - 1].cam_from_world, ds.views()[i].cam_from_world);
  }
  j["cameras"] = cameras;
  j["mean_step_deg"] = ds.NumViews() > 1 ? step_sum / (ds.NumViews() - 1) : 0.0;
  const BoundingBox& b = ds.bbox();
  j["bbox"] = {{"min", {b.min.x(), b.min.y(), b.min.z()}},
               {"max", {b.max.x(), b.max.y(), b.max.z()}},
               {"source", ds.bbox_source()}};
  for (double angle : {5.0, 15.0}) {
    const NeighbourStats s = Stats(ViewGraph(dirs, angle));
    j["neighbours_within_" + std::to_string(static_cast<int>(angle)) + "deg"] = {
        {"mean", s.mean}, {"min", s.min}, {"max", s.max}, {"isolated", s.isolated}};
  }
  int gt_depth = 0;
  for (int i = 0; i < ds.NumViews(); ++i) gt_depth += ds.GroundTruthDepthPath(i).has_value();
  j["ground_truth"] = {{"depth_maps", gt_depth},
                       {"mesh", ds.GroundTruthMeshPath(false).has_value()},
                       {"thin_mesh", ds.GroundTruthMeshPath(true).has_value()}};
  if (as_json) {
    std::cout << j.dump(2) << "\n";
    return 0;
  }
  std::cout << "dataset      " << (ds.root().empty() ? "(explicit sources)" : ds.root().string()) << "\n";
  std::cout << "views        " << ds.NumViews() << " (poses from " << ds.pose_source() << "), mean step "
            << j["mean_step_deg"].get<double>() << " deg\n";
  for (const auto& [k, n] : cameras) std::cout << "camera       " << k << " (" << n << " views)\n";
  std::cout << "V            [" << b.min.transpose() << "] .. [" << b.max.transpose() << "] m, size ["
            << b.Extent().transpose() << "] (from " << ds.bbox_source() << ")\n";
  for (double angle : {5.0, 15.0}) {
    const auto& s = j["neighbours_within_" + std::to_string(static_cast<int>(angle)) + "deg"];
    std::cout << "within " << angle << " deg" << (angle < 10 ? " " : "") << " mean " << s["mean"].get<double>()
              << ", min " << s["min"] << ", max " << s["max"] << " neighbours; " << s["isolated"]
              << " views with none\n";
  }
  std::cout << "ground truth " << gt_depth << " depth maps, mesh " << (j["ground_truth"]["mesh"] ? "yes" : "no")
            << ", thin mesh " << (j["ground_truth"]["thin_mesh"] ? "yes" : "no") << "\n";
  return 0;
}

}  // namespace

void AddInfoCommand(CLI::App& root, int* exit_code) {
  auto* cmd = root.add_subcommand("info", "Summarise a dataset: views, cameras, volume V, neighbours, ground truth");
  auto flags = std::make_shared<DatasetFlags>();
  auto as_json = std::make_shared<bool>(false);
  flags->AddTo(cmd);
  cmd->add_flag("--json", *as_json, "Print the summary as JSON on stdout");
  cmd->callback([flags, as_json, exit_code] { *exit_code = RunInfo(*flags, *as_json); });
}

}  // namespace lfrecon::cli
