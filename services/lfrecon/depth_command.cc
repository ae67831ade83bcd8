// `lfrecon depth`: per-view depth maps (sparse §3.1, filtered §3.2) written as
// PFM with colour-mapped previews; `lfrecon eval-depth`: their accuracy and
// coverage against ground-truth depth.
#include <spdlog/spdlog.h>

#include <filesystem>
#include <map>
#include <memory>
#include <iostream>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "commands.h"
#include "dataset_flags.h"
#include "depth/streaming_depth.h"
#include "eval/depth_metrics.h"
#include "geometry/view_graph.h"
#include "propagation/depth_propagator.h"
#include "propagation/edge_preview.h"
#include "io/dataset.h"
#include "io/depth_map_io.h"
#include "util/error.h"
#include "util/memory.h"
#include "util/progress.h"

namespace lfrecon::cli {
namespace fs = std::filesystem;

namespace {

std::string Stem(const std::string& name) { return fs::path(name).stem().string(); }

struct DepthArgs {
  DatasetFlags data;
  fs::path out;
  std::string views;
  std::string stage = "filtered";
};

int RunDepth(const DepthArgs& args) {
  const Dataset ds = Dataset::Open(args.data.Resolve());
  if (args.stage != "sparse" && args.stage != "filtered" && args.stage != "dense")
    throw OptionError("--stage must be sparse, filtered or dense");
  const bool dense = args.stage == "dense";
  const std::vector<int> wanted = ParseViewRange(args.views, ds.NumViews());
  StreamingDepthOptions options;
  options.run_filter = args.stage != "sparse";  // dense densifies the filtered map
  std::vector<PinholeView> views;
  for (int i = 0; i < ds.NumViews(); ++i) views.push_back(ds.View(i));
  for (const char* sub : {"depth", "confidence", "preview"}) fs::create_directories(args.out / sub);
  if (dense) fs::create_directories(args.out / "edges");
  auto frames = ds.OpenFrames();
  StreamingDepth stage(views, ds.bbox(), options);

  // Dense (§4) needs the frames within 5° of each wanted view: keep a
  // reference-counted window of them, filled by the depth stage's frame tap.
  PropagationOptions popt;
  popt.photo.presmooth_sigma = options.gradient.presmooth_sigma;  // reuse the depth stage's smoothed frames
  const DepthPropagator propagator(popt);
  std::vector<int> refs(views.size(), 0);
  std::map<int, ViewImage> window;
  std::unique_ptr<ViewGraph> near;
  if (dense) {
    near = std::make_unique<ViewGraph>(ViewingDirections(views), popt.photo.max_view_angle_deg);
    for (int i : wanted) {
      ++refs[i];
      for (int j : near->Neighbors(i)) ++refs[j];
    }
    stage.SetFrameTap([&](int f, const ViewImage& v, const cv::Mat&) {
      if (refs[f] > 0) window[f] = v;
    });
  }
  spdlog::info("depth: {} of {} views, stage {}, output {}", wanted.size(), ds.NumViews(), args.stage,
               args.out.string());
  Timer timer;
  long long valid = 0;
  const StreamingDepthStats stats =
      stage.Run(*frames, wanted, [&](int i, const cv::Mat& image, const DepthMap& sparse, const DepthMap& filtered) {
        const std::string stem = Stem(ds.views()[i].name);
        DepthMap densified;
        if (dense) {
          std::vector<const ViewImage*> nbs;
          for (int j : near->Neighbors(i))
            if (window.count(j)) nbs.push_back(&window.at(j));
          const DenseDepthResult r = propagator.Run(window.at(i), nbs, filtered, ds.bbox());
          densified = r.dense;
          WriteEdgePreview(args.out / "edges" / (stem + ".png"), image, r.edges.Classify(popt.photo.silhouette_ratio));
          for (int j : near->Neighbors(i))
            if (--refs[j] == 0) window.erase(j);
          if (--refs[i] == 0) window.erase(i);
        }
        const DepthMap& m = dense ? densified : options.run_filter ? filtered : sparse;
        WritePfm(args.out / "depth" / (stem + ".pfm"), m.depth);
        WritePfm(args.out / "confidence" / (stem + ".pfm"), m.confidence);
        WriteDepthPreview(args.out / "preview" / (stem + ".png"), m.depth, image);
        valid += m.CountValid();
      });
  spdlog::info("depth: {} maps in {:.1f} s ({:.0f} ms/view sparse, {:.0f} ms/view filter), {} frames read, "
               "at most {} frames held, peak RSS {:.0f} MiB",
               wanted.size(), timer.Seconds(), 1000 * stats.seconds_sparse / std::max(1, stats.sparse_maps),
               1000 * stats.seconds_filter / std::max(1, stats.filtered_maps), stats.frames_read,
               stats.max_frames_held, PeakRssBytes() / 1048576.0);
  std::cout << "wrote " << wanted.size() << " depth maps (" << valid << " pixels with depth) to "
            << (args.out / "depth").string() << "\n";
  return 0;
}

struct EvalDepthArgs {
  DatasetFlags data;
  fs::path depth_dir;
  bool json = false;
  bool dense = false;
};

int RunEvalDepth(const EvalDepthArgs& args) {
  const Dataset ds = Dataset::Open(args.data.Resolve());
  if (!fs::is_directory(args.depth_dir)) throw InputError(args.depth_dir.string(), "no such folder");
  const fs::path conf_dir = args.depth_dir.parent_path() / "confidence";
  DepthMetricsOptions options;
  options.dense = args.dense;
  auto frames = ds.OpenFrames();
  DepthMetrics total;
  nlohmann::json per_view = nlohmann::json::array();
  int views = 0;
  for (int i = 0; i < ds.NumViews(); ++i) {
    const auto gt_path = ds.GroundTruthDepthPath(i);
    const fs::path est_path = args.depth_dir / (Stem(ds.views()[i].name) + ".pfm");
    if (!gt_path || !fs::exists(est_path)) continue;
    DepthMap m;
    m.depth = ReadPfm(est_path);
    const fs::path cp = conf_dir / est_path.filename();
    m.confidence = fs::exists(cp) ? ReadPfm(cp) : cv::Mat(m.depth.size(), CV_32F, cv::Scalar(1.0f));
    const cv::Mat gt = ReadDepthMap(*gt_path);
    if (gt.size() != m.depth.size())
      throw InputError(est_path.string(), "size " + std::to_string(m.depth.cols) + "x" + std::to_string(m.depth.rows) +
                                              " differs from the ground truth's");
    const cv::Mat image = frames->Read(i).image;
    const DepthMetrics vm = EvaluateDepth(m, gt, image, ds.View(i), ds.bbox(), options);
    per_view.push_back({{"view", ds.views()[i].name}, {"accuracy", vm.Accuracy()}, {"coverage", vm.Coverage()}});
    if (!args.json)
      std::cout << ds.views()[i].name << ": accuracy " << vm.Accuracy() << " coverage " << vm.Coverage() << "\n";
    total.Add(vm);
    ++views;
  }
  if (views == 0)
    throw InputError(args.depth_dir.string(), "no depth map matches a view with ground truth (expected <image-stem>.pfm)");
  nlohmann::json curve = nlohmann::json::array();
  for (const CurvePoint& p : AccuracyCoverageCurve(total, 10))
    curve.push_back({{"min_confidence", p.min_confidence}, {"accuracy", p.accuracy}, {"coverage", p.coverage}});
  if (args.json) {
    nlohmann::json j = {{"views", views},          {"accuracy", total.Accuracy()}, {"coverage", total.Coverage()},
                        {"tolerance", options.relative_tolerance}, {"dense", args.dense}, {"per_view", per_view},
                        {"curve", curve}};
    std::cout << j.dump(2) << "\n";
  } else {
    std::cout << "TOTAL over " << views << " views: accuracy " << total.Accuracy() << " coverage "
              << total.Coverage() << " (within " << 100 * options.relative_tolerance << "% of true depth)\n";
    for (const auto& p : curve)
      std::cout << "  confidence >= " << p["min_confidence"].get<double>() << ": accuracy "
                << p["accuracy"].get<double>() << " coverage " << p["coverage"].get<double>() << "\n";
  }
  return 0;
}

}  // namespace

void AddDepthCommand(CLI::App& root, int* exit_code) {
  auto args = std::make_shared<DepthArgs>();
  auto* cmd = root.add_subcommand(
      "depth", "Per-view depth maps: sparse depth from gradients (§3.1), filtered (§3.2), dense (§4)");
  args->data.AddTo(cmd);
  cmd->add_option("--out", args->out, "Output folder (depth/, confidence/, preview/)")->required();
  cmd->add_option("--views", args->views, "Views to write, A:B:STEP (0-based, B exclusive); default all");
  cmd->add_option("--stage", args->stage, "sparse (§3.1), filtered (§3.2) or dense (§4; also writes edges/ previews)")
      ->capture_default_str();
  cmd->callback([args, exit_code] { *exit_code = RunDepth(*args); });

  auto eargs = std::make_shared<EvalDepthArgs>();
  auto* ecmd = root.add_subcommand("eval-depth", "Accuracy and coverage of depth maps against ground-truth depth");
  eargs->data.AddTo(ecmd);
  ecmd->add_option("--depth", eargs->depth_dir, "Folder of <image-stem>.pfm depth maps (confidence/ beside it)")
      ->required();
  ecmd->add_flag("--json", eargs->json, "Print JSON on stdout");
  ecmd->add_flag("--dense", eargs->dense, "Dense maps: coverage over all foreground pixels, not only edges");
  ecmd->callback([eargs, exit_code] { *exit_code = RunEvalDepth(*eargs); });
}

}  // namespace lfrecon::cli
