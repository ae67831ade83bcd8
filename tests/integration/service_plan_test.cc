// The service and `lfrecon run` follow one reconstruction plan: on a generated
// arc spaced 0.3° apart (under the hierarchy grid's 0.5°, where the workers
// used to thin neighbours differently for want of on_grid flags), the same
// views are selected (every fourth: 1.2°, with the selection at >= 1°, the job option and run flag --view-step-deg 1), get
// sparse maps (the selected views only: they are the filter's voters) and give
// bit-identical dense maps; the fused meshes then agree.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <memory>
#include <nlohmann/json.hpp>
#include <thread>

#include "common/job_store.h"
#include "common/messaging.h"
#include "common/stored_depth.h"
#include "common/test_util.h"
#include "eval/mesh_metrics.h"
#include "integration/daemon_process.h"
#include "io/dataset.h"
#include "io/depth_map_io.h"
#include "io/ply.h"

namespace lfrecon::svc {
namespace {
namespace fs = std::filesystem;
using lfrecon::testing::DaemonProcess;
using lfrecon::testing::RunShell;

const std::string kBin = std::string(LFRECON_BINARY_DIR) + "/bin/";
constexpr int kFrames = 80;  // 0.3° apart: a 24° arc
constexpr double kVoxelMm = 6.0;
const std::string kViewStep = " --view-step-deg 1";  // the job option and run's flag alike

std::string Sh(const std::string& cmd) {
  const auto r = RunShell(cmd);
  EXPECT_EQ(r.code, 0) << cmd << "\n" << r.output;
  return r.output;
}

TEST(ServicePlan, DenseArcServiceEqualsRunWithOnePlan) {
  lfrecon::testing::TempDir tmp;
  const fs::path data = tmp.path() / "dataset", run_dir = tmp.path() / "run", store = tmp.path() / "store";
  Sh(kBin + "lfrecon -q synth --scene sphere --frames " + std::to_string(kFrames) + " --loops " +
      std::to_string(kFrames * 0.3 / 360.0) + " --width 160 --height 90 --depth-every 0 --out " + data.string());
  // lfrecon run with the poses as given (as the service), its fused maps written.
  // The views selected >= 1° apart (kViewStep), so that every fourth view of the 0.3° arc is selected.
  Sh(kBin + "lfrecon -q run --dataset " + data.string() + " --no-refine-poses --no-refine --write-depth --voxel-mm " +
      std::to_string(kVoxelMm) + kViewStep + " --out " + run_dir.string());
  const nlohmann::json report = nlohmann::json::parse(ReadFileBytes(run_dir / "report.json"));
  const int selected = report["views"]["processed"];
  EXPECT_EQ(selected, kFrames / 4);  // 0.3° apart, selected >= 1° apart: every fourth view
  EXPECT_EQ(report["views"]["total"], kFrames);

  // The service: one worker per stage, so tasks are taken in view order, as run takes them.
  const std::string agg = "ipc://" + (tmp.path() / "agg.sock").string();
  const std::string ing = "ipc://" + (tmp.path() / "ing.sock").string();
  std::vector<std::unique_ptr<DaemonProcess>> procs;
  auto start = [&](const std::string& exe, std::vector<std::string> args) {
    args.insert(args.begin(), kBin + exe);
    procs.push_back(std::make_unique<DaemonProcess>(args, tmp.path() / (exe + ".log")));
  };
  start("lfrecon-aggregate", {"--bind", agg, "--store", store.string()});
  start("lfrecon-ingest", {"--bind", ing, "--aggregate", agg, "--store", store.string()});
  start("lfrecon-depth", {"--aggregate", agg, "--store", store.string()});
  start("lfrecon-propagate", {"--aggregate", agg, "--store", store.string()});
  std::string job = Sh(kBin + "lfrecon -q submit --ingest " + ing + " --dataset " + data.string() + " --voxel-mm " +
                        std::to_string(kVoxelMm) + kViewStep);
  job.erase(job.find_last_not_of('\n') + 1);
  ASSERT_TRUE(JobStore::ValidJobId(job)) << job;
  const std::string st = Sh(kBin + "lfrecon status " + job + " --wait --wait-s 400 --json --aggregate " + agg);
  const nlohmann::json status = nlohmann::json::parse(st);
  EXPECT_EQ(status["state"], "DONE") << st;
  EXPECT_EQ(status["views"], selected);         // the views to fuse: the plan's selection
  EXPECT_EQ(status["views_fused"], selected);
  EXPECT_EQ(status["sparse_done"], selected);   // sparse maps of the selected views only (the filter's voters)
  EXPECT_EQ(status["frames_spooled"], kFrames);
  for (auto& p : procs) EXPECT_EQ(p->Stop(), 0) << p->Log();
  // What each depth task read: the plan's depth neighbours (14 of the 28 frames
  // within 5° for interior views), not every frame within 5°.
  const std::string depth_log = procs[2]->Log();
  EXPECT_NE(depth_log.find("stopped after"), std::string::npos) << depth_log;

  // Same plan, same inputs: every selected view's dense map, as fused (its
  // stored map and own-depth mask checked against the stored maps of its plan
  // neighbours), is bit-identical to lfrecon run's.
  DatasetOptions d;
  d.dataset_dir = data;
  const Dataset ds = Dataset::Open(d);
  JobStore js(store);
  const JobGeometry geo = LoadJobGeometry(js, job);
  StoredDepthCache depths(js, job, 32);
  long long dropped = 0;
  int compared = 0, identical = 0;
  for (int v = 0; v < ds.NumViews(); ++v) {
    const fs::path pfm = run_dir / "depth" / (fs::path(ds.views()[v].name).stem().string() + ".pfm");
    const bool in_run = fs::exists(pfm), in_service = js.HasMap(job, pb::MAP_DENSE, v);
    EXPECT_EQ(in_run, in_service) << "view " << v;
    EXPECT_EQ(in_run, v % 4 == 0) << "view " << v;
    if (!in_run || !in_service) continue;
    const cv::Mat a = ReadPfm(pfm);
    cv::Mat own;
    DepthMap b = js.ReadMap(job, pb::MAP_DENSE, v, ds.View(v), &own);
    EXPECT_FALSE(own.empty()) << "view " << v << ": the propagation worker marks its own depths";
    dropped += CheckStoredDenseMap(geo, v, own, &depths, &b, nullptr).dropped;
    ++compared;
    identical += cv::norm(a, b.depth, cv::NORM_INF) == 0;
  }
  EXPECT_EQ(compared, selected);
  EXPECT_EQ(identical, compared);

  // The fused meshes: views integrated in the order they arrived (here view order, as run's).
  const TriangleMesh run_mesh = ReadPly(run_dir / "mesh_raw.ply");
  const TriangleMesh svc_mesh = ReadPly(store / job / "mesh_raw.ply");
  ASSERT_GT(run_mesh.triangles.size(), 100u);
  std::printf("dense arc: %d of %d views selected; %d/%d dense maps identical (%lld depths dropped by the geometric "
              "consistency check); mesh_raw run %zu, service %zu triangles\n",
              selected, kFrames, identical, compared, dropped, run_mesh.triangles.size(), svc_mesh.triangles.size());
  EXPECT_EQ(svc_mesh.triangles.size(), run_mesh.triangles.size());
  EXPECT_EQ(svc_mesh.vertices.size(), run_mesh.vertices.size());
  double max_dv = 0;
  if (svc_mesh.vertices.size() == run_mesh.vertices.size())
    for (std::size_t k = 0; k < svc_mesh.vertices.size(); ++k)
      max_dv = std::max(max_dv, static_cast<double>((svc_mesh.vertices[k] - run_mesh.vertices[k]).norm()));
  std::printf("largest vertex difference %.3g m\n", max_dv);
  EXPECT_EQ(max_dv, 0.0);
}

}  // namespace
}  // namespace lfrecon::svc
