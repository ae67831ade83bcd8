// `lfrecon submit --max-image-size N` reaches the ingest daemon's reading: the
// job's manifest holds the scaled cameras and its spooled frames are the
// dataset's frames read at that size (issue 17).
#include <gtest/gtest.h>

#include <chrono>
#include <opencv2/core.hpp>
#include <thread>

#include "common/job_store.h"
#include "common/test_util.h"
#include "daemon_process.h"
#include "io/dataset.h"

namespace lfrecon {
namespace {

namespace fs = std::filesystem;
using lfrecon::svc::JobStore;
using testing::DaemonProcess;
using testing::RunShell;

const std::string kBin = std::string(LFRECON_BINARY_DIR) + "/bin/";

TEST(SubmitOptions, MaxImageSizeReachesIngest) {
  testing::TempDir tmp;
  const fs::path data = tmp.path() / "data", store = tmp.path() / "store";
  const auto synth = RunShell(kBin + "lfrecon -q synth --scene sphere --frames 6 --width 96 --height 54 --out " +
                              data.string());
  ASSERT_EQ(synth.code, 0) << synth.output;
  const std::string agg = "ipc://" + (tmp.path() / "agg.sock").string();
  const std::string ing = "ipc://" + (tmp.path() / "ing.sock").string();
  DaemonProcess aggregate({kBin + "lfrecon-aggregate", "--bind", agg, "--store", store.string()},
                          tmp.path() / "aggregate.log");
  DaemonProcess ingest({kBin + "lfrecon-ingest", "--bind", ing, "--aggregate", agg, "--store", store.string()},
                       tmp.path() / "ingest.log");
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  const auto sub = RunShell(kBin + "lfrecon -q submit --ingest " + ing + " --dataset " + data.string() +
                            " --max-image-size 48");
  ASSERT_EQ(sub.code, 0) << sub.output << ingest.Log();
  std::string job = sub.output.substr(0, sub.output.find('\n'));
  ASSERT_TRUE(JobStore::ValidJobId(job)) << sub.output;

  DatasetOptions options;
  options.dataset_dir = data;
  options.max_image_size = 48;
  const Dataset half = Dataset::Open(options);
  const JobStore js(store);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(120);
  while (!js.HasFrame(job, half.NumViews() - 1) && std::chrono::steady_clock::now() < deadline)
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
  ASSERT_TRUE(js.HasFrame(job, half.NumViews() - 1)) << ingest.Log() << aggregate.Log();
  const auto manifest = js.ReadManifest(job);
  EXPECT_EQ(manifest.spec().max_image_size(), 48u);
  ASSERT_EQ(manifest.views_size(), half.NumViews());
  EXPECT_EQ(manifest.views(0).width(), 48u);
  EXPECT_EQ(manifest.views(0).height(), 27u);
  const PinholeView v = half.View(2);
  EXPECT_DOUBLE_EQ(v.K(0, 0), half.views()[2].camera.fx());
  const cv::Mat spooled = js.ReadFrame(job, 2, v);
  auto frames = half.OpenFrames();
  const Frame expect = frames->Read(2);
  ASSERT_EQ(spooled.size(), cv::Size(48, 27));
  EXPECT_LT(cv::norm(spooled, expect.image, cv::NORM_INF), 1e-6);
}

}  // namespace
}  // namespace lfrecon
