// The streaming service end to end: separate daemon processes (ingest,
// aggregate, N depth and N propagate workers) over ipc:// sockets on a small
// synthetic job, compared with `lfrecon run` on the same data.
#include <signal.h>
#include <unistd.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>
#include <thread>

#include "common/job_store.h"
#include "common/messaging.h"
#include "common/test_util.h"
#include "daemon_process.h"
#include "eval/mesh_metrics.h"
#include "io/dataset.h"
#include "io/ply.h"
#include "reference_dataset.h"
#include "service_stack.h"

namespace lfrecon::svc {
namespace {
namespace fs = std::filesystem;
using std::chrono::milliseconds;

using lfrecon::testing::DaemonProcess;
using lfrecon::testing::kBin;
using lfrecon::testing::MakeReference;
using lfrecon::testing::ReferenceDataset;
using lfrecon::testing::RemoveReference;
using lfrecon::testing::ScoreAgainstReference;
using lfrecon::testing::ServiceStackTest;

constexpr double kVoxelMm = lfrecon::testing::kReferenceVoxelMm;

// Runs a command, returns its stdout; fails the test on a non-zero exit.
std::string RunCommand(const std::string& cmd) {
  std::string out;
  FILE* p = ::popen(cmd.c_str(), "r");
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof(buf), p)) > 0) out.append(buf, n);
  const int rc = ::pclose(p);
  EXPECT_EQ(rc, 0) << cmd << "\n" << out;
  return out;
}

// One synthetic dataset and the embedded pipeline's result on it, for all tests.
ReferenceDataset* g_ref = nullptr;

MeshMetrics Score(const TriangleMesh& mesh) { return ScoreAgainstReference(mesh, *g_ref); }

class ServiceTest : public ServiceStackTest {
 protected:
  static void SetUpTestSuite() {
    g_ref = new ReferenceDataset;
    MakeReference("service_ref", /*with_run=*/true, g_ref);
    if (!g_ref->has_run) return;
    std::printf("lfrecon run: mesh_raw %zu triangles, F@%.0fmm %.4f, F@%.0fmm %.4f; mesh (refined) %zu triangles, "
                "%.4f, %.4f\n",
                g_ref->triangles, 2 * kVoxelMm, g_ref->f2, 4 * kVoxelMm, g_ref->f4, g_ref->refined_triangles,
                g_ref->refined_f2, g_ref->refined_f4);
  }
  static void TearDownTestSuite() {
    RemoveReference(*g_ref);
    delete g_ref;
  }

  void SetUp() override {
    ServiceStackTest::SetUp();
    client_ = std::make_unique<RequestClient>(context_, agg_);
  }
  void TearDown() override {
    ServiceStackTest::TearDown();
    client_.reset();
  }

  std::string Submit() {
    std::string out = RunCommand(kBin + "lfrecon -q submit --ingest " + ing_ + " --dataset " + g_ref->dataset.string() +
                                 " --voxel-mm " + std::to_string(kVoxelMm));
    out.erase(out.find_last_not_of("\n") + 1);
    EXPECT_TRUE(JobStore::ValidJobId(out)) << out;
    return out;
  }

  pb::Envelope Ask(pb::Envelope req, int timeout_ms = 5000) {
    auto r = client_->Request(req, milliseconds(timeout_ms));
    EXPECT_TRUE(r.has_value()) << "no reply to " << BodyName(req);
    return r ? *r : ErrorEnvelope(pb::ERROR_UNKNOWN, "no reply");
  }
  pb::JobStatus Status(const std::string& job) override {  // through client_, a missing reply fails
    pb::Envelope req = NewEnvelope(job);
    req.mutable_status();
    const pb::Envelope r = Ask(req);
    EXPECT_TRUE(r.has_job_status()) << (r.has_error() ? r.error().message() : BodyName(r));
    return r.job_status();
  }
  // Polls until `pred` holds for the job's status (or fails after `timeout_s`).
  template <typename Pred>
  pb::JobStatus WaitUntil(const std::string& job, Pred pred, double timeout_s = 240) {
    const auto t0 = std::chrono::steady_clock::now();
    pb::JobStatus s;
    while (std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count() < timeout_s) {
      auto r = client_->Request([&] {
        pb::Envelope req = NewEnvelope(job);
        req.mutable_status();
        return req;
      }(), milliseconds(2000));
      if (r && r->has_job_status()) {
        s = r->job_status();
        if (pred(s)) return s;
        if (s.state() == pb::STATE_FAILED) break;
      }
      std::this_thread::sleep_for(milliseconds(50));
    }
    ADD_FAILURE() << "job " << job << " did not reach the expected state: " << pb::JobState_Name(s.state()) << " "
                  << s.views_fused() << "/" << s.num_views() << " fused: " << s.message();
    return s;
  }
  pb::JobStatus WaitDone(const std::string& job) {
    return WaitUntil(job, [](const pb::JobStatus& s) { return s.state() == pb::STATE_DONE; });
  }
  pb::ExportReply Export(const std::string& job, const fs::path& out, bool refine = false) {
    pb::Envelope req = NewEnvelope(job);
    req.mutable_export_request()->set_refine(refine);
    const pb::Envelope r = Ask(req, 60000);
    EXPECT_TRUE(r.has_export_reply()) << (r.has_error() ? r.error().message() : BodyName(r));
    std::ofstream(out, std::ios::binary) << r.export_reply().ply();
    return r.export_reply();
  }
  // The final mesh through the CLI, scored against lfrecon run's: the fused one
  // (mesh_raw.ply), or with `refine` the refined one (mesh.ply).
  void ExpectSameAsEmbedded(const std::string& job, bool refine = false) {
    const fs::path out = tmp_.path() / (refine ? "final_refined.ply" : "final.ply");
    const auto t0 = std::chrono::steady_clock::now();
    RunCommand(kBin + "lfrecon -q export " + job + (refine ? " --refine" : "") + " --aggregate " + agg_ + " -o " +
               out.string());
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    const TriangleMesh mesh = ReadPly(out);
    const MeshMetrics m = Score(mesh);
    const double f2 = refine ? g_ref->refined_f2 : g_ref->f2, f4 = refine ? g_ref->refined_f4 : g_ref->f4;
    std::printf("service%s: %zu triangles, F@%.0fmm %.4f, F@%.0fmm %.4f (lfrecon run %s: %zu, %.4f, %.4f); export "
                "%.2f s\n",
                refine ? " (export --refine)" : "", mesh.triangles.size(), 2 * kVoxelMm, m.scores[0].fscore,
                4 * kVoxelMm, m.scores[1].fscore, refine ? "mesh.ply" : "mesh_raw.ply",
                refine ? g_ref->refined_triangles : g_ref->triangles, f2, f4, seconds);
    EXPECT_GT(f4, 0.5);  // the reference itself is a reconstruction
    EXPECT_NEAR(m.scores[0].fscore, f2, 1e-3);
    EXPECT_NEAR(m.scores[1].fscore, f4, 1e-3);
  }

  std::unique_ptr<RequestClient> client_;
};

TEST_F(ServiceTest, SubmittedJobOnSeparateProcessesEqualsEmbeddedRun) {
  StartStack(2);
  const std::string job = Submit();
  const pb::JobStatus s = WaitDone(job);
  EXPECT_EQ(s.views_fused(), static_cast<unsigned>(g_ref->views));
  EXPECT_EQ(s.frames_spooled(), static_cast<unsigned>(g_ref->views));
  ExpectSameAsEmbedded(job);
  // status and cancel through the CLI; a finished job stays DONE.
  const std::string st = RunCommand(kBin + "lfrecon status " + job + " --json --aggregate " + agg_);
  EXPECT_NE(st.find("\"DONE\""), std::string::npos) << st;
  // export --refine: carving + screened Poisson of the job's grid, rebuilt from
  // its checkpoint, equals lfrecon run's mesh.ply; kept, so the next one is the same file.
  ExpectSameAsEmbedded(job, true);
  const pb::ExportReply again = Export(job, tmp_.path() / "again.ply", true);
  EXPECT_TRUE(again.complete());
  EXPECT_EQ(again.views_fused(), static_cast<unsigned>(g_ref->views));
  EXPECT_EQ(again.ply(), ReadFileBytes(tmp_.path() / "final_refined.ply"));
  EXPECT_TRUE(fs::exists(store_ / job / "mesh_refined.ply"));
  // Cancelling a finished job leaves it DONE.
  pb::Envelope cancel = NewEnvelope(job);
  cancel.mutable_cancel();
  EXPECT_EQ(Ask(cancel).job_status().state(), pb::STATE_DONE);
  // Daemons stop cleanly on SIGTERM.
  for (auto& p : procs_) EXPECT_EQ(p->Stop(), 0) << p->log();
}

// The test plays ingest: frames go into the store and are announced out of
// order, some twice; halfway the mesh is exported (valid, growing).
TEST_F(ServiceTest, FramesOutOfOrderAndDuplicatedAndExportMidStream) {
  StartAggregator();
  StartWorker("lfrecon-depth");
  StartWorker("lfrecon-propagate");
  JobStore store(store_);
  pb::JobSpec spec;
  spec.set_dataset_dir(g_ref->dataset.string());
  spec.mutable_options()->set_voxel_size(kVoxelMm / 1000);
  const Dataset ds = Dataset::Open(ToDatasetOptions(spec));
  const std::string job = store.CreateJob();
  store.WriteManifest(MakeManifest(job, spec, ds));
  pb::Envelope created = NewEnvelope(job);
  created.mutable_job_created()->set_num_views(ds.NumViews());
  ASSERT_TRUE(Ask(created).has_ack());

  const int n = ds.NumViews();
  std::vector<pb::Frame> frames;
  auto source = ds.OpenFrames();
  Frame f;
  for (int k = 0; source->Next(&f); ++k) frames.push_back(FrameToProto(k, f.image, CameraToProto(ds.View(k), "")));
  ASSERT_EQ(static_cast<int>(frames.size()), n);
  std::mt19937 rng(7);
  auto spool = [&](int a, int b) {
    std::vector<int> order;
    for (int k = a; k < b; ++k) {
      order.push_back(k);
      if (k % 7 == 0) order.push_back(k);  // duplicates
    }
    std::shuffle(order.begin(), order.end(), rng);
    for (int k : order) {
      store.WriteFrame(job, frames[k]);
      pb::Envelope env = NewEnvelope(job);
      env.mutable_frame_spooled()->set_index(k);
      ASSERT_TRUE(Ask(env).has_ack());
    }
  };
  spool(0, n / 2);
  const pb::JobStatus mid1 = WaitUntil(job, [](const pb::JobStatus& s) { return s.views_fused() >= 20; });
  const pb::ExportReply e1 = Export(job, tmp_.path() / "mid1.ply");
  const TriangleMesh m1 = ReadPly(tmp_.path() / "mid1.ply");
  EXPECT_FALSE(e1.complete());
  EXPECT_GE(e1.views_fused(), mid1.views_fused());
  EXPECT_LT(e1.views_fused(), static_cast<unsigned>(n));
  EXPECT_GT(m1.triangles.size(), 100u);
  EXPECT_EQ(m1.triangles.size(), e1.triangles());
  for (const auto& t : m1.triangles)
    for (int k = 0; k < 3; ++k) ASSERT_LT(static_cast<std::size_t>(t[k]), m1.vertices.size());
  // Refined mid-stream: of the views fused when asked (the job keeps running meanwhile).
  const auto t_refine = std::chrono::steady_clock::now();
  const pb::ExportReply r1 = Export(job, tmp_.path() / "mid1_refined.ply", true);
  const TriangleMesh mr1 = ReadPly(tmp_.path() / "mid1_refined.ply");
  std::printf("mid-stream export --refine: %u views -> %zu triangles (%.2f s)\n", r1.views_fused(),
              mr1.triangles.size(),
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t_refine).count());
  EXPECT_FALSE(r1.complete());
  EXPECT_GE(r1.views_fused(), e1.views_fused());
  EXPECT_GT(mr1.triangles.size(), 100u);
  EXPECT_EQ(mr1.triangles.size(), r1.triangles());
  for (const auto& t : mr1.triangles)
    for (int k = 0; k < 3; ++k) ASSERT_LT(static_cast<std::size_t>(t[k]), mr1.vertices.size());
  spool(n / 2, n);
  WaitUntil(job, [&](const pb::JobStatus& s) { return s.views_fused() >= e1.views_fused() + 30; });
  const pb::ExportReply e2 = Export(job, tmp_.path() / "mid2.ply");
  const TriangleMesh m2 = ReadPly(tmp_.path() / "mid2.ply");
  std::printf("mid-stream exports: %u views -> %zu triangles, %u views -> %zu triangles\n", e1.views_fused(),
              m1.triangles.size(), e2.views_fused(), m2.triangles.size());
  EXPECT_GT(e2.views_fused(), e1.views_fused());
  EXPECT_GT(m2.triangles.size(), m1.triangles.size());
  for (int rep = 0; rep < 2; ++rep) {  // IngestDone twice, too
    pb::Envelope done = NewEnvelope(job);
    done.mutable_ingest_done()->set_num_frames(n);
    ASSERT_TRUE(Ask(done).has_ack());
  }
  WaitDone(job);
  ExpectSameAsEmbedded(job);
}

// A job whose frames never come: cancel ends it, no task is handed out for it.
TEST_F(ServiceTest, CancelStopsAJob) {
  StartAggregator();
  JobStore store(store_);
  pb::JobSpec spec;
  spec.set_dataset_dir(g_ref->dataset.string());
  const std::string job = store.CreateJob();
  store.WriteManifest(MakeManifest(job, spec, Dataset::Open(ToDatasetOptions(spec))));
  EXPECT_EQ(Status(job).state(), pb::STATE_INGESTING);
  for (int k = 0; k < 3; ++k) {
    store.WriteFrame(job, FrameToProto(k, cv::Mat(54, 96, CV_32FC3, cv::Scalar::all(0.5)), pb::Camera()));
    pb::Envelope env = NewEnvelope(job);
    env.mutable_frame_spooled()->set_index(k);
    ASSERT_TRUE(Ask(env).has_ack());
  }
  EXPECT_EQ(Status(job).frames_spooled(), 3u);
  pb::Envelope cancel = NewEnvelope(job);
  cancel.mutable_cancel();
  EXPECT_EQ(Ask(cancel).job_status().state(), pb::STATE_CANCELLED);
  EXPECT_EQ(Status(job).state(), pb::STATE_CANCELLED);
  EXPECT_TRUE(store.ReadText(job, "cancelled").has_value());  // ingest stops at its next frame
  for (bool refine : {false, true}) {  // nothing to export, refined or not: a clear error
    pb::Envelope ex = NewEnvelope(job);
    ex.mutable_export_request()->set_refine(refine);
    const pb::Envelope r = Ask(ex);
    EXPECT_EQ(r.error().code(), pb::ERROR_BAD_REQUEST) << r.error().message();
    EXPECT_NE(r.error().message().find("CANCELLED"), std::string::npos) << r.error().message();
  }
  pb::Envelope tr = NewEnvelope();
  tr.mutable_task_request()->set_stage(pb::STAGE_DEPTH);
  EXPECT_TRUE(Ask(tr).has_no_task());
  const std::string out = RunCommand(kBin + "lfrecon status " + job + " --aggregate " + agg_);
  EXPECT_NE(out.find("CANCELLED"), std::string::npos) << out;
}

TEST_F(ServiceTest, KilledDepthWorkerViewsAreRedone) {
  StartAggregator({"--lease-ms", "1500"});
  StartIngest();
  DaemonProcess* doomed = StartWorker("lfrecon-depth", {"--stall-after-tasks", "3"});
  const std::string job = Submit();
  // The doomed worker holds its 4th view; kill it mid-task, then the others join.
  WaitUntil(job, [](const pb::JobStatus& s) { return s.sparse_done() >= 3; });
  std::this_thread::sleep_for(milliseconds(300));
  EXPECT_TRUE(doomed->Running());
  doomed->Kill(SIGKILL);
  StartWorker("lfrecon-depth");
  StartWorker("lfrecon-propagate");
  const pb::JobStatus s = WaitDone(job);
  EXPECT_GE(s.leases_expired(), 1u);
  EXPECT_EQ(s.views_fused(), static_cast<unsigned>(g_ref->views));
  ExpectSameAsEmbedded(job);
}

TEST_F(ServiceTest, AggregatorRestartResumesFromCheckpoint) {
  DaemonProcess* agg = StartAggregator();
  StartIngest();
  StartWorker("lfrecon-depth");
  StartWorker("lfrecon-propagate");
  const std::string job = Submit();
  const pb::JobStatus before = WaitUntil(job, [&](const pb::JobStatus& s) { return s.views_fused() >= 30; });
  agg->Kill(SIGKILL);
  const auto fused_log = JobStore(store_).ReadText(job, "fused.log");
  ASSERT_TRUE(fused_log.has_value());
  const int logged = static_cast<int>(std::count(fused_log->begin(), fused_log->end(), '\n'));
  EXPECT_GE(logged, static_cast<int>(before.views_fused()));
  StartAggregator();
  client_ = std::make_unique<RequestClient>(context_, agg_);
  // Resumed: every stored map counts as received at once; what was fused is fused again (replayed in the background).
  const pb::JobStatus after = Status(job);
  EXPECT_GE(after.dense_done(), static_cast<unsigned>(logged));
  EXPECT_NE(after.state(), pb::STATE_DONE);
  WaitUntil(job, [&](const pb::JobStatus& s) { return s.views_fused() >= static_cast<unsigned>(logged); });
  WaitDone(job);
  ExpectSameAsEmbedded(job);
}

// Milliseconds of one status request (fails the test if unanswered).
double TimedStatus(RequestClient& client, const std::string& job, pb::JobStatus* status) {
  pb::Envelope req = NewEnvelope(job);
  req.mutable_status();
  const auto t0 = std::chrono::steady_clock::now();
  const auto r = client.Request(req, milliseconds(10000));
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_TRUE(r && r->has_job_status()) << "no status reply";
  if (r && r->has_job_status()) *status = r->job_status();
  return ms;
}

// Dense maps in the store and views in fused.log.
std::pair<int, int> StoredAndLogged(const fs::path& store_dir, const std::string& job, int views) {
  JobStore store(store_dir);
  int stored = 0;
  for (int v = 0; v < views; ++v) stored += store.HasMap(job, pb::MAP_DENSE, v);
  const auto log = store.ReadText(job, "fused.log");
  return {stored, log ? static_cast<int>(std::count(log->begin(), log->end(), '\n')) : 0};
}

// Slow fusion (--fusion-delay-ms: each view holds the grid 1.5 s longer, as a
// big grid's integration takes): the serving thread never waits for it, so
// status is answered in milliseconds while received maps queue for fusion (the
// aggregator used to fuse on its serving thread: every status waited >= 1.5 s).
// A mid-stream export waits for the view being integrated (never half a view).
// SIGTERM stops the fusion thread after its view, the maps not fused yet stay
// in the store, and a restarted aggregator fuses them: lfrecon run's mesh.
TEST_F(ServiceTest, StatusAnsweredWhileFusingAndStopMidQueue) {
  DaemonProcess* agg = StartAggregator({"--fusion-delay-ms", "1500"});
  StartIngest();
  StartWorker("lfrecon-depth");
  StartWorker("lfrecon-propagate");
  const std::string job = Submit();
  WaitUntil(job, [](const pb::JobStatus& s) { return s.views_fused() >= 3; });
  std::vector<double> ms;
  int fusing = 0;
  for (int i = 0; i < 10; ++i) {
    pb::JobStatus s;
    ms.push_back(TimedStatus(*client_, job, &s));
    fusing += s.dense_done() > s.views_fused();  // received maps wait: the fusion thread is busy
    std::this_thread::sleep_for(milliseconds(150));
  }
  std::sort(ms.begin(), ms.end());
  std::printf("status while fusing (1.5 s per view): median %.1f ms, worst %.1f ms of %zu\n", ms[ms.size() / 2],
              ms.back(), ms.size());
  EXPECT_EQ(fusing, 10);
  EXPECT_LT(ms.back(), 500.0);
  // Export mid-stream: the views fused when it got the grid.
  const pb::JobStatus s0 = Status(job);
  const pb::ExportReply e = Export(job, tmp_.path() / "mid.ply");
  const pb::JobStatus s1 = Status(job);
  EXPECT_FALSE(e.complete());
  EXPECT_GE(e.views_fused(), s0.views_fused());
  EXPECT_LE(e.views_fused(), s1.views_fused());
  EXPECT_EQ(ReadPly(tmp_.path() / "mid.ply").triangles.size(), e.triangles());
  // SIGTERM mid-queue: a clean exit after the view under way.
  const auto t_stop = std::chrono::steady_clock::now();
  EXPECT_EQ(agg->Stop(), 0);
  std::printf("aggregator stopped in %.2f s\n",
              std::chrono::duration<double>(std::chrono::steady_clock::now() - t_stop).count());
  const auto [stored, logged] = StoredAndLogged(store_, job, g_ref->views);
  EXPECT_LT(logged, stored);  // acknowledged maps not fused yet: in the store
  StartAggregator();
  client_ = std::make_unique<RequestClient>(context_, agg_);
  pb::Envelope ping = NewEnvelope();
  ping.mutable_ping();
  EXPECT_TRUE(Ask(ping).has_pong());  // up (the process start is not timed)
  pb::JobStatus after;
  EXPECT_LT(TimedStatus(*client_, job, &after), 500.0);  // answered at once, the checkpoint replays meanwhile
  EXPECT_GE(after.dense_done(), static_cast<unsigned>(stored));
  const pb::JobStatus done = WaitDone(job);
  EXPECT_EQ(done.views_fused(), static_cast<unsigned>(g_ref->views));
  EXPECT_EQ(StoredAndLogged(store_, job, g_ref->views).second, g_ref->views);  // each view logged once
  ExpectSameAsEmbedded(job);
}

// Cancel while views wait for fusion: answered at once, the fusion thread
// stops after the view it is integrating, nothing more is fused.
TEST_F(ServiceTest, CancelWhileFusing) {
  DaemonProcess* agg = StartAggregator({"--fusion-delay-ms", "1500"});
  StartIngest();
  StartWorker("lfrecon-depth");
  StartWorker("lfrecon-propagate");
  const std::string job = Submit();
  WaitUntil(job, [](const pb::JobStatus& s) { return s.views_fused() >= 2; });
  pb::Envelope cancel = NewEnvelope(job);
  cancel.mutable_cancel();
  const auto t0 = std::chrono::steady_clock::now();
  const pb::Envelope r = Ask(cancel);
  const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  EXPECT_EQ(r.job_status().state(), pb::STATE_CANCELLED);
  EXPECT_GT(r.job_status().dense_done(), r.job_status().views_fused());  // maps were waiting for fusion
  EXPECT_LT(ms, 500.0);
  std::this_thread::sleep_for(milliseconds(2000));  // the view under way: its delay stops at the cancel
  const int logged = StoredAndLogged(store_, job, g_ref->views).second;
  EXPECT_LE(logged, static_cast<int>(r.job_status().views_fused()) + 1);
  std::this_thread::sleep_for(milliseconds(1500));
  EXPECT_EQ(StoredAndLogged(store_, job, g_ref->views).second, logged);  // stopped
  EXPECT_EQ(Status(job).state(), pb::STATE_CANCELLED);
  pb::Envelope ex = NewEnvelope(job);
  ex.mutable_export_request();
  EXPECT_EQ(Ask(ex).error().code(), pb::ERROR_BAD_REQUEST);
  EXPECT_EQ(agg->Stop(), 0);
  EXPECT_NE(agg->LogTail(100000).find("fusion thread stopped"), std::string::npos);
}

TEST_F(ServiceTest, BadMessagesGetErrorRepliesAndDaemonsKeepServing) {
  StartAggregator({"--max-message-mb", "1"});
  StartIngest({"--max-message-mb", "1"});
  for (const std::string& endpoint : {agg_, ing_}) {
    RequestClient c(context_, endpoint, 64ll << 20);
    auto expect_error = [&](const std::optional<pb::Envelope>& r, pb::ErrorCode code, const std::string& what) {
      ASSERT_TRUE(r.has_value()) << endpoint << ": no reply to " << what;
      ASSERT_TRUE(r->has_error()) << endpoint << ": " << what << " got " << BodyName(*r);
      EXPECT_EQ(r->error().code(), code) << endpoint << ": " << what << ": " << r->error().message();
    };
    auto ping = [&] {
      pb::Envelope p = NewEnvelope();
      p.mutable_ping();
      auto r = c.Request(p, milliseconds(5000));
      ASSERT_TRUE(r.has_value()) << endpoint << " stopped answering";
      EXPECT_TRUE(r->has_pong()) << BodyName(*r);
    };
    expect_error(c.RequestRaw("\xff\xff\xff garbage, not protobuf", milliseconds(5000)), pb::ERROR_MALFORMED, "garbage");
    ping();
    expect_error(c.RequestRaw("", milliseconds(5000)), pb::ERROR_MALFORMED, "empty message");
    pb::Envelope old = NewEnvelope();
    old.set_version(kProtocolVersion + 1);
    old.mutable_ping();
    expect_error(c.Request(old, milliseconds(5000)), pb::ERROR_VERSION, "wrong version");
    pb::Envelope big = NewEnvelope("x");
    big.mutable_frame()->set_data(std::string(3 << 19, 'a'));  // 1.5 MiB > 1 MiB
    expect_error(c.Request(big, milliseconds(5000)), pb::ERROR_TOO_LARGE, "oversized");
    ping();
    // Beyond the transport limit ZeroMQ drops the connection: no reply, daemon unharmed.
    pb::Envelope huge = NewEnvelope("x");
    huge.mutable_frame()->set_data(std::string(8 << 20, 'a'));
    EXPECT_FALSE(c.Request(huge, milliseconds(1500)).has_value());
    ping();
  }
  // Unknown and invalid job ids, and requests a daemon does not serve.
  for (const std::string& id : {std::string("j-no-such-job"), std::string("../etc"), std::string()}) {
    pb::Envelope st = NewEnvelope(id);
    st.mutable_status();
    const pb::Envelope r = Ask(st);
    ASSERT_TRUE(r.has_error()) << id;
    EXPECT_EQ(r.error().code(), pb::ERROR_UNKNOWN_JOB) << r.error().message();
    pb::Envelope ex = NewEnvelope(id);
    ex.mutable_export_request();
    EXPECT_EQ(Ask(ex).error().code(), pb::ERROR_UNKNOWN_JOB);
  }
  {
    RequestClient ingest(context_, ing_);
    pb::Envelope sub = NewEnvelope();
    sub.mutable_submit()->mutable_spec()->set_dataset_dir((tmp_.path() / "missing").string());
    auto r = ingest.Request(sub, milliseconds(5000));
    ASSERT_TRUE(r && r->has_error());
    EXPECT_EQ(r->error().code(), pb::ERROR_INPUT) << r->error().message();
    EXPECT_NE(r->error().message().find("missing"), std::string::npos) << r->error().message();
    pb::Envelope st = NewEnvelope("j");
    st.mutable_status();
    r = ingest.Request(st, milliseconds(5000));
    ASSERT_TRUE(r && r->has_error());
    EXPECT_EQ(r->error().code(), pb::ERROR_BAD_REQUEST);
  }
  // A worker's result for an unknown job, and a task request for an unknown stage.
  pb::Envelope res = NewEnvelope("j-no-such-job");
  res.mutable_task_result()->set_view(0);
  EXPECT_EQ(Ask(res).error().code(), pb::ERROR_UNKNOWN_JOB);
  pb::Envelope tr = NewEnvelope();
  tr.mutable_task_request()->set_stage(static_cast<pb::Stage>(42));
  EXPECT_EQ(Ask(tr).error().code(), pb::ERROR_BAD_REQUEST);
  // Still serving.
  pb::Envelope p = NewEnvelope();
  p.mutable_ping();
  EXPECT_TRUE(Ask(p).has_pong());
  for (auto& proc : procs_) EXPECT_TRUE(proc->Running()) << proc->log();
}

}  // namespace
}  // namespace lfrecon::svc
