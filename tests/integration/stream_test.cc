// Client-pushed streams (proto/README.md "Streams"): `lfrecon stream` of a
// generated loop spaced under 0.5° gives lfrecon run's mesh, also when its
// views are planned and fused while it streams (a frame-gap bound); a client faster
// than ingest is held to its credits; repeated and out-of-order frames follow
// the documented policy (a repeat is ignored, any order is accepted, gaps fail
// the job at the end); a client that dies mid-stream fails its job after the
// stream timeout. Real daemons over ipc:// in a temporary folder.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <memory>
#include <nlohmann/json.hpp>
#include <thread>

#include "common/job_store.h"
#include "common/messaging.h"
#include "common/stored_depth.h"
#include "common/stream_client.h"
#include "common/test_util.h"
#include "io/dataset.h"
#include "io/depth_map_io.h"
#include "io/ply.h"
#include "service_stack.h"

namespace lfrecon::svc {
namespace {
namespace fs = std::filesystem;
using lfrecon::testing::DaemonProcess;
using lfrecon::testing::kBin;
using lfrecon::testing::RunShell;
using lfrecon::testing::ServiceStackTest;
using lfrecon::testing::Sh;
using std::chrono::milliseconds;

constexpr double kVoxelMm = 6.0;
// The arcs below are 0.3° apart and their views selected >= 1° apart (every fourth), as run and the job
// alike (the default step, 2°, would keep every seventh).
const std::string kViewStep = " --view-step-deg 1";

std::string LastLine(std::string s) {
  s.erase(s.find_last_not_of('\n') + 1);
  const auto nl = s.rfind('\n');
  return nl == std::string::npos ? s : s.substr(nl + 1);
}

class StreamTest : public ServiceStackTest {
 protected:
  // A small generated dataset: `frames` frames 0.3° apart.
  // JPEG frames (the store keeps their bytes; the daemons decode the bytes lfrecon run decodes).
  fs::path Synth(int frames, int width, int height) {
    const fs::path data = tmp_.path() / "dataset";
    Sh(kBin + "lfrecon -q synth --scene sphere --frames " + std::to_string(frames) + " --loops " +
       std::to_string(frames * 0.3 / 360.0) + " --width " + std::to_string(width) + " --height " +
       std::to_string(height) + " --depth-every 0 --no-meshes --format jpg --out " + data.string());
    return data;
  }
  // The frames of `data` as a client pushes them.
  std::vector<pb::Frame> Frames(const fs::path& data, BoundingBox* volume) {
    DatasetOptions d;
    d.dataset_dir = data;
    const Dataset ds = Dataset::Open(d);
    *volume = ds.bbox();
    StoreFrameEncoder enc(ds);
    std::vector<pb::Frame> out;
    for (int k = 0; k < ds.NumViews(); ++k) out.push_back(enc.Encode(k, false));
    return out;
  }
  static pb::StreamOpen Open(const BoundingBox& v, int credits) {
    pb::StreamOpen open;
    for (int k = 0; k < 3; ++k) open.mutable_spec()->add_bbox(v.min(k));
    for (int k = 0; k < 3; ++k) open.mutable_spec()->add_bbox(v.max(k));
    open.set_credits(static_cast<std::uint32_t>(credits));
    return open;
  }
};

// `lfrecon stream` of a 0.3°-spaced arc: the job's plan (computed at the end
// of the stream from every camera) is lfrecon run's, so the same views get the
// same bit-identical dense maps and the fused meshes are the same.
TEST_F(StreamTest, StreamOfDenseArcEqualsRun) {
  constexpr int kFrames = 40;
  const fs::path data = Synth(kFrames, 160, 90);
  const fs::path run_dir = tmp_.path() / "run";
  Sh(kBin + "lfrecon -q run --dataset " + data.string() + " --no-refine-poses --no-refine --write-depth --voxel-mm " +
     std::to_string(kVoxelMm) + kViewStep + " --out " + run_dir.string());
  const nlohmann::json report = nlohmann::json::parse(ReadFileBytes(run_dir / "report.json"));
  const int selected = report["views"]["processed"];
  EXPECT_EQ(selected, kFrames / 4);  // 0.3° apart, selected >= 1° apart: every fourth view
  StartStack(1);
  const fs::path stats = tmp_.path() / "stats.json", follow = tmp_.path() / "follow.ply";
  const std::string out = Sh(kBin + "lfrecon -q stream --ingest " + ing_ + " --aggregate " + agg_ + " --dataset " +
                             data.string() + " --voxel-mm " + std::to_string(kVoxelMm) + kViewStep + " --credits 4 --stats " +
                             stats.string() + " --follow " + follow.string() + " --follow-s 0.5 --wait-s 400");
  const std::string job = out.substr(0, out.find('\n'));
  ASSERT_TRUE(JobStore::ValidJobId(job)) << out;
  EXPECT_NE(LastLine(out).find("DONE"), std::string::npos) << out;
  const nlohmann::json st = nlohmann::json::parse(ReadFileBytes(stats));
  EXPECT_EQ(st["frames"], kFrames);
  EXPECT_LE(st["max_in_flight"].get<int>(), 4);
  EXPECT_LE(st["max_in_flight_ingest"].get<int>(), 4);
  EXPECT_LE(st["bytes_per_pixel"].get<double>(), 1.5);
  const pb::JobStatus s = Status(job);
  EXPECT_EQ(s.state(), pb::STATE_DONE) << s.message();
  EXPECT_EQ(s.frames_spooled(), static_cast<unsigned>(kFrames));
  EXPECT_EQ(s.views_fused(), static_cast<unsigned>(selected));
  // The manifest: the stream's cameras, as the dataset's.
  JobStore js(store_);
  const pb::JobManifest m = js.ReadManifest(job);
  EXPECT_EQ(m.pose_source(), "stream");
  ASSERT_EQ(m.views_size(), kFrames);
  DatasetOptions d;
  d.dataset_dir = data;
  const Dataset ds = Dataset::Open(d);
  // Each stored dense map as the aggregator fused it (geometric consistency with its plan neighbours' maps).
  const JobGeometry geo = LoadJobGeometry(js, job);
  StoredDepthCache depths(js, job, 32);
  int compared = 0, identical = 0;
  for (int v = 0; v < kFrames; ++v) {
    const fs::path pfm = run_dir / "depth" / (fs::path(ds.views()[v].name).stem().string() + ".pfm");
    EXPECT_EQ(fs::exists(pfm), js.HasMap(job, pb::MAP_DENSE, v)) << "view " << v;
    if (!fs::exists(pfm) || !js.HasMap(job, pb::MAP_DENSE, v)) continue;
    ++compared;
    cv::Mat own;
    DepthMap fused = js.ReadMap(job, pb::MAP_DENSE, v, ds.View(v), &own);
    CheckStoredDenseMap(geo, v, own, &depths, &fused, nullptr);
    identical += cv::norm(ReadPfm(pfm), fused.depth, cv::NORM_INF) == 0;
  }
  EXPECT_EQ(compared, selected);
  EXPECT_EQ(identical, compared);
  const TriangleMesh run_mesh = ReadPly(run_dir / "mesh_raw.ply");
  const TriangleMesh svc_mesh = ReadPly(store_ / job / "mesh_raw.ply");
  ASSERT_GT(run_mesh.triangles.size(), 100u);
  ASSERT_EQ(svc_mesh.vertices.size(), run_mesh.vertices.size());
  EXPECT_EQ(svc_mesh.triangles.size(), run_mesh.triangles.size());
  double max_dv = 0;
  for (std::size_t k = 0; k < svc_mesh.vertices.size(); ++k)
    max_dv = std::max(max_dv, static_cast<double>((svc_mesh.vertices[k] - run_mesh.vertices[k]).norm()));
  EXPECT_EQ(max_dv, 0.0);
  // --follow wrote the final mesh (the job's coloured mesh.ply).
  ASSERT_TRUE(fs::exists(follow));
  EXPECT_EQ(ReadPly(follow).triangles.size(), ReadPly(store_ / job / "mesh.ply").triangles.size());
  std::printf("stream: %d frames, %.1f frames/s, %.3f bytes a pixel stored, at most %d in flight; %d/%d dense maps "
              "identical to lfrecon run's, mesh_raw %zu vertices, largest difference %.3g m\n",
              kFrames, st["frames_per_second"].get<double>(), st["bytes_per_pixel"].get<double>(),
              st["max_in_flight"].get<int>(), identical, compared, svc_mesh.vertices.size(), max_dv);
}

// The growing plan (issue 14 §1): a stream that gives V and a frame-gap bound
// is planned as its frames arrive. Views whose plan entries no later frame can
// change (ReconstructionPlan::SettledFrames) are leased while the stream is
// open, and fused once the 8 views after them in the plan's order are final
// too (geometric consistency): status counts them, and `--follow` and a
// mid-stream export return a mesh that grows. At the end the whole plan is
// lfrecon run's (--max-frame-gap alike), so the mesh is the same. A second
// stream survives kill -9 of the aggregator mid-stream: the restarted one
// resumes the open stream from the store and its checkpoint, and ends with the
// same mesh. 150 frames: the first view is fused once ~80 are in.
TEST_F(StreamTest, GrowingPlanFusesWhileStreamingAndEqualsRun) {
  constexpr int kFrames = 150, kGap = 15;
  const fs::path data = Synth(kFrames, 96, 54);
  const std::string gap = " --max-frame-gap " + std::to_string(kGap);
  const std::string voxel = " --voxel-mm " + std::to_string(kVoxelMm) + kViewStep;
  const fs::path run_dir = tmp_.path() / "run";
  Sh(kBin + "lfrecon -q run --dataset " + data.string() + " --no-refine-poses --no-refine" + voxel + gap + " --out " +
     run_dir.string());
  const nlohmann::json report = nlohmann::json::parse(ReadFileBytes(run_dir / "report.json"));
  const int selected = report["views"]["processed"];
  EXPECT_EQ(selected, (kFrames + 3) / 4);  // every fourth view (0.3° apart, selected >= 1°): 0, 4, ..., 148
  const TriangleMesh run_mesh = ReadPly(run_dir / "mesh_raw.ply");
  ASSERT_GT(run_mesh.triangles.size(), 100u);
  auto largest_difference = [](const TriangleMesh& m, const TriangleMesh& run) {
    EXPECT_EQ(m.vertices.size(), run.vertices.size());
    EXPECT_EQ(m.triangles.size(), run.triangles.size());
    if (m.vertices.size() != run.vertices.size()) return 1e9;
    double d = 0;
    for (std::size_t k = 0; k < m.vertices.size(); ++k)
      d = std::max(d, static_cast<double>((m.vertices[k] - run.vertices[k]).norm()));
    return d;
  };
  StartStack(1);
  JobStore js(store_);
  auto export_vertices = [&](const std::string& job) -> long {
    RequestClient c(context_, agg_);
    pb::Envelope req = NewEnvelope(job);
    req.mutable_export_request();
    auto r = c.Request(req, milliseconds(20000));
    return r && r->has_export_reply() ? static_cast<long>(r->export_reply().vertices()) : -1;
  };

  // 1. `lfrecon stream --follow` at a camera's pace, watched from outside while it streams.
  const fs::path follow = tmp_.path() / "follow.ply";
  DaemonProcess* cli = Start("lfrecon", {"-q", "stream", "--ingest", ing_, "--aggregate", agg_, "--dataset",
                                         data.string(), "--voxel-mm", std::to_string(kVoxelMm), "--view-step-deg", "1", "--max-frame-gap",
                                         std::to_string(kGap), "--rate", "10", "--credits", "4", "--follow",
                                         follow.string(), "--follow-s", "0.3", "--wait-s", "400"});
  std::string job;
  for (int i = 0; i < 200 && job.empty(); ++i) {
    std::this_thread::sleep_for(milliseconds(50));
    const std::string log = cli->Log();
    if (log.find('\n') != std::string::npos) job = log.substr(0, log.find('\n'));
  }
  ASSERT_TRUE(JobStore::ValidJobId(job)) << cli->Log();
  int fused_open = 0, frames_first_fused = 0;  // views fused while open; frames received when the first was seen
  std::vector<long> exports_open, follow_open;
  std::string message_open;
  while (cli->Running()) {
    const pb::JobStatus s = Status(job);
    if (s.state() == pb::STATE_INGESTING && s.views_fused() > 0) {
      if (fused_open == 0) frames_first_fused = static_cast<int>(s.frames_spooled());
      fused_open = std::max<int>(fused_open, static_cast<int>(s.views_fused()));
      // The first such status: at the stream's very end the aggregator may have read its
      // end (the whole plan) before ingest's notice moves the state on, with no message.
      if (message_open.empty()) message_open = s.message();
      const long v = export_vertices(job);
      if (Status(job).state() == pb::STATE_INGESTING && v > 0) exports_open.push_back(v);
      if (fs::exists(follow) && Status(job).state() == pb::STATE_INGESTING)
        follow_open.push_back(static_cast<long>(ReadPly(follow).vertices.size()));
    }
    std::this_thread::sleep_for(milliseconds(150));
  }
  EXPECT_EQ(cli->WaitExit(milliseconds(1000)), 0) << cli->LogTail();
  EXPECT_NE(LastLine(cli->Log()).find("DONE"), std::string::npos) << cli->LogTail();
  // Views were fused while the stream was open, and the mesh grew meanwhile.
  EXPECT_GT(fused_open, 0);
  EXPECT_LT(frames_first_fused, kFrames);
  EXPECT_NE(message_open.find("stream open"), std::string::npos) << message_open;
  ASSERT_FALSE(exports_open.empty());
  ASSERT_FALSE(follow_open.empty());
  EXPECT_GT(*std::max_element(follow_open.begin(), follow_open.end()), 0);
  // The end: lfrecon run's views and mesh.
  pb::JobStatus s = Status(job);
  EXPECT_EQ(s.state(), pb::STATE_DONE) << s.message();
  EXPECT_EQ(s.views_fused(), static_cast<unsigned>(selected));
  const double followed_difference = largest_difference(ReadPly(store_ / job / "mesh_raw.ply"), run_mesh);
  EXPECT_EQ(followed_difference, 0.0);

  // 2. Pushed by a client; the aggregator killed (-9) once views are fused, and restarted.
  // Without the geometric consistency check (JobOptions.no_geometric_consistency): with it a
  // view waits for the 8 views after it in the plan's order, and on this 90-frame arc only
  // 4 of the 23 views are fused before the end (part 1 sees them), too few to kill mid-way.
  // Its end is lfrecon run --no-geometric-consistency's mesh.
  Sh(kBin + "lfrecon -q run --dataset " + data.string() + " --no-refine-poses --no-refine --no-geometric-consistency" +
     voxel + gap + " --out " + (tmp_.path() / "run_unchecked").string());
  const TriangleMesh run_unchecked = ReadPly(tmp_.path() / "run_unchecked" / "mesh_raw.ply");
  BoundingBox v;
  const std::vector<pb::Frame> frames = Frames(data, &v);
  StreamClient client(context_, ing_);
  pb::StreamOpen open = Open(v, 4);
  open.mutable_spec()->mutable_options()->set_voxel_size(kVoxelMm / 1000.0);
  open.mutable_spec()->mutable_options()->set_max_frame_gap(kGap);
  open.mutable_spec()->mutable_options()->set_view_step_deg(1.0);
  open.mutable_spec()->mutable_options()->set_no_geometric_consistency(true);
  client.Open(open, milliseconds(10000));
  const std::string job2 = client.job_id();
  constexpr int kBeforeKill = 60;
  for (int k = 0; k < kBeforeKill; ++k) client.Push(frames[static_cast<std::size_t>(k)], milliseconds(10000));
  for (int i = 0; i < 600 && Status(job2).views_fused() == 0; ++i) std::this_thread::sleep_for(milliseconds(100));
  const pb::JobStatus before = Status(job2);
  EXPECT_EQ(before.state(), pb::STATE_INGESTING);
  EXPECT_GT(before.views_fused(), 0u);
  const long vertices_before = export_vertices(job2);
  EXPECT_GT(vertices_before, 0);
  procs_[0]->Kill(SIGKILL);
  Start("lfrecon-aggregate", {"--bind", agg_, "--store", store_.string()});
  for (int k = kBeforeKill; k < kFrames; ++k) client.Push(frames[static_cast<std::size_t>(k)], milliseconds(10000));
  // Every frame is in, the end not yet: the views before the last frame - 2 gaps (every fourth one) are
  // settled and all get fused; the rest wait for the end.
  const unsigned settled_views = (kFrames - 2 * kGap) / 4;
  for (int i = 0; i < 1200 && Status(job2).views_fused() < settled_views; ++i)
    std::this_thread::sleep_for(milliseconds(100));
  std::this_thread::sleep_for(milliseconds(500));
  const pb::JobStatus open_all = Status(job2);
  EXPECT_EQ(open_all.state(), pb::STATE_INGESTING);
  EXPECT_EQ(open_all.views_fused(), settled_views);
  const long vertices_open = export_vertices(job2);
  // The restarted aggregator fused more views into the open stream's mesh. Not "more vertices":
  // a mesh from a few views 1.2° apart is rougher and can have more (4010 after 4 views, 3825
  // after 15, measured), and the end is checked against lfrecon run's mesh below.
  EXPECT_GT(open_all.views_fused(), before.views_fused());
  EXPECT_GT(vertices_open, 0);
  EXPECT_NE(vertices_open, vertices_before);
  EXPECT_EQ(client.End(kFrames, milliseconds(60000)).num_frames(), static_cast<unsigned>(kFrames));
  for (int i = 0; i < 1200 && !(s = Status(job2), s.state() == pb::STATE_DONE || s.state() == pb::STATE_FAILED); ++i)
    std::this_thread::sleep_for(milliseconds(100));
  EXPECT_EQ(s.state(), pb::STATE_DONE) << s.message();
  EXPECT_EQ(s.views_fused(), static_cast<unsigned>(selected));
  const double restarted_difference = largest_difference(ReadPly(store_ / job2 / "mesh_raw.ply"), run_unchecked);
  EXPECT_EQ(restarted_difference, 0.0);
  std::printf("growing plan: %d frames (gap %d), %d of %d views fused while open (the first seen at %d frames), "
              "mid-stream exports %ld -> %ld vertices, %zu --follow meshes while open; mesh_raw vs lfrecon run: "
              "largest difference %.3g m; aggregator killed after %u views fused (%d frames pushed, %ld vertices), "
              "%u fused before the end (%ld vertices): %.3g m\n",
              kFrames, kGap, fused_open, selected, frames_first_fused, exports_open.front(), exports_open.back(),
              follow_open.size(), followed_difference, before.views_fused(), kBeforeKill, vertices_before,
              open_all.views_fused(), vertices_open, restarted_difference);
}

// A client faster than ingest (each frame takes ingest 40 ms to store): it is
// held to its 3 credits, ingest never has more than 3 of its frames, and one
// that ignores the credits is refused (ERROR_BUSY) instead of buffered.
TEST_F(StreamTest, FastClientIsBoundedByCredits) {
  const fs::path data = Synth(16, 64, 36);
  BoundingBox v;
  const std::vector<pb::Frame> frames = Frames(data, &v);
  StartStack(0, {"--frame-delay-ms", "40"});
  StreamClient client(context_, ing_);
  const pb::StreamOpened opened = client.Open(Open(v, 3), milliseconds(10000));
  EXPECT_EQ(opened.credits(), 3u);
  const auto start = std::chrono::steady_clock::now();
  for (const pb::Frame& f : frames) {
    client.Push(f, milliseconds(10000));
    EXPECT_LE(client.in_flight(), 3);
  }
  const pb::StreamEnded ended = client.End(static_cast<std::uint32_t>(frames.size()), milliseconds(30000));
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_EQ(ended.num_frames(), frames.size());
  EXPECT_EQ(client.max_in_flight(), 3);  // it did run ahead, as far as its credits
  EXPECT_LE(ended.max_in_flight(), 3u);
  EXPECT_GE(ended.max_in_flight(), 2u);
  EXPECT_GE(seconds, 16 * 0.040 * 0.9);  // slowed to ingest's pace
  // Ignoring the credits: 8 frames at once to a 2-credit stream; the ones beyond the credits are refused.
  StreamClient rude(context_, ing_);
  rude.Open(Open(v, 2), milliseconds(10000));
  for (int k = 0; k < 8; ++k) {
    pb::Envelope env = NewEnvelope();
    *env.mutable_stream_frame()->mutable_frame() = frames[static_cast<std::size_t>(k)];
    rude.SendUnchecked(env);
  }
  int busy = 0, credits = 0;
  for (int k = 0; k < 8; ++k) {
    auto r = rude.Receive(milliseconds(10000));
    ASSERT_TRUE(r.has_value());
    busy += r->has_error() && r->error().code() == pb::ERROR_BUSY;
    credits += r->has_stream_credit();
  }
  EXPECT_GE(busy, 5);
  EXPECT_EQ(busy + credits, 8);
  std::printf("credits: 16 frames in %.2f s (ingest 40 ms a frame), at most %d in flight (ingest %u); a client "
              "ignoring 2 credits: %d of 8 refused\n",
              seconds, client.max_in_flight(), ended.max_in_flight(), busy);
}

// Policy: any order is accepted; a repeated index is ignored (the first copy
// kept, answered `repeated`); the end needs frames 0..n-1, a gap fails the job.
TEST_F(StreamTest, OutOfOrderAcceptedRepeatIgnoredGapFails) {
  const fs::path data = Synth(6, 64, 36);
  BoundingBox v;
  const std::vector<pb::Frame> frames = Frames(data, &v);
  StartStack(0);
  StreamClient client(context_, ing_);
  client.Open(Open(v, 4), milliseconds(10000));
  pb::Frame changed = frames[1];
  changed.mutable_camera()->set_name("second copy");
  for (int k : {3, 1, 0, 5, 2, 4}) client.Push(frames[static_cast<std::size_t>(k)], milliseconds(10000));
  client.Push(changed, milliseconds(10000));
  const pb::StreamEnded ended = client.End(6, milliseconds(30000));
  EXPECT_EQ(ended.num_frames(), 6u);
  EXPECT_EQ(client.repeated(), 1);
  JobStore js(store_);
  const pb::JobManifest m = js.ReadManifest(client.job_id());
  ASSERT_EQ(m.views_size(), 6);
  for (int k = 0; k < 6; ++k) EXPECT_EQ(m.views(k).name(), frames[static_cast<std::size_t>(k)].camera().name());
  EXPECT_EQ(Status(client.job_id()).frames_spooled(), 6u);
  // A gap: frames 0, 1, 3 then the end.
  StreamClient gap(context_, ing_);
  gap.Open(Open(v, 4), milliseconds(10000));
  for (int k : {0, 1, 3}) gap.Push(frames[static_cast<std::size_t>(k)], milliseconds(10000));
  try {
    gap.End(0, milliseconds(30000));
    ADD_FAILURE() << "a stream with a gap ended";
  } catch (const ServiceError& e) {
    EXPECT_NE(std::string(e.what()).find("frame 2"), std::string::npos) << e.what();
  }
  const pb::JobStatus s = Status(gap.job_id());
  EXPECT_EQ(s.state(), pb::STATE_FAILED);
  EXPECT_NE(s.message().find("missing"), std::string::npos) << s.message();
  // A frame whose image does not match its camera is refused (not stored); the stream goes on.
  StreamClient bad(context_, ing_);
  bad.Open(Open(v, 4), milliseconds(10000));
  pb::Frame wrong = frames[0];
  wrong.mutable_source()->set_stored_width(wrong.source().stored_width() * 2);
  wrong.mutable_source()->set_width(wrong.source().width() * 2);
  wrong.mutable_camera()->set_width(wrong.camera().width() * 2);
  pb::Envelope env = NewEnvelope();
  *env.mutable_stream_frame()->mutable_frame() = wrong;
  bad.SendUnchecked(env);
  auto r = bad.Receive(milliseconds(10000));
  ASSERT_TRUE(r.has_value());
  ASSERT_TRUE(r->has_error());
  EXPECT_EQ(r->error().code(), pb::ERROR_INPUT);
  EXPECT_NE(r->error().message().find("image header is 64x36 but its camera is 128x36"), std::string::npos)
      << r->error().message();
  bad.Push(frames[0], milliseconds(10000));  // the same index again, now whole: stored
  EXPECT_EQ(bad.End(1, milliseconds(30000)).num_frames(), 1u);
}

// Intrinsics (and the source camera) once per job: frames carry only their
// pose; a raw 8-bit frame ("bgr8") is stored as lossless PNG; the manifest has
// every frame's full camera.
TEST_F(StreamTest, IntrinsicsOncePerJobAndRawFrames) {
  const fs::path data = Synth(4, 64, 36);
  BoundingBox v;
  const std::vector<pb::Frame> frames = Frames(data, &v);
  StartStack(0);
  StreamClient client(context_, ing_);
  pb::StreamOpen open = Open(v, 2);
  pb::Camera* intr = open.mutable_intrinsics();
  intr->set_width(frames[0].camera().width());
  intr->set_height(frames[0].camera().height());
  *intr->mutable_k() = frames[0].camera().k();
  *open.mutable_source() = frames[0].source();
  client.Open(open, milliseconds(10000));
  for (int k = 0; k < 3; ++k) {
    pb::Frame f = frames[static_cast<std::size_t>(k)];
    f.mutable_camera()->clear_k();
    f.mutable_camera()->clear_width();
    f.mutable_camera()->clear_height();
    f.clear_source();
    client.Push(f, milliseconds(10000));
  }
  // Frame 3 raw: the decoded pixels as 8-bit BGR.
  pb::Frame raw = frames[3];
  const cv::Mat img = FrameFromProto(raw, 64, 36, "frame 3");
  cv::Mat u8;
  img.convertTo(u8, CV_8U, 255.0);
  raw.clear_source();
  raw.set_encoding("bgr8");
  raw.set_data(std::string(reinterpret_cast<const char*>(u8.data), u8.total() * 3));
  client.Push(raw, milliseconds(10000));
  EXPECT_EQ(client.End(4, milliseconds(30000)).num_frames(), 4u);
  JobStore js(store_);
  const pb::JobManifest m = js.ReadManifest(client.job_id());
  ASSERT_EQ(m.views_size(), 4);
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(m.views(k).k_size(), 9);
    EXPECT_EQ(m.views(k).width(), 64u);
    const PinholeView view = CameraFromProto(m.views(k), "manifest");
    EXPECT_EQ(cv::norm(js.ReadFrame(client.job_id(), k, view), FrameFromProto(frames[static_cast<std::size_t>(k)], 64, 36, "f"),
                       cv::NORM_INF),
              0.0)
        << "frame " << k;
  }
  pb::Frame stored;
  ASSERT_TRUE(stored.ParseFromString(ReadFileBytes(js.FramePath(client.job_id(), 3))));
  EXPECT_EQ(stored.encoding(), "png");
  // Without V: estimated from the cameras at the end, as io/Dataset estimates it.
  StreamClient nov(context_, ing_);
  pb::StreamOpen open_nov;
  open_nov.set_credits(2);
  nov.Open(open_nov, milliseconds(10000));
  for (const pb::Frame& f : frames) nov.Push(f, milliseconds(10000));
  EXPECT_EQ(nov.End(4, milliseconds(30000)).num_frames(), 4u);
  const pb::JobManifest mv = js.ReadManifest(nov.job_id());
  EXPECT_EQ(mv.bbox_source(), "estimated");
  EXPECT_EQ(mv.volume().min_size(), 3);
}

// A client that dies mid-stream: after --stream-timeout-s without a message the
// job fails with the reason (it never waits for ever); frames after that are refused.
TEST_F(StreamTest, ClientGoneMidStreamFailsTheJob) {
  const fs::path data = Synth(6, 64, 36);
  BoundingBox v;
  const std::vector<pb::Frame> frames = Frames(data, &v);
  StartStack(0, {"--stream-timeout-s", "1"});
  std::string job;
  {
    StreamClient client(context_, ing_);
    client.Open(Open(v, 4), milliseconds(10000));
    job = client.job_id();
    for (int k = 0; k < 3; ++k) client.Push(frames[static_cast<std::size_t>(k)], milliseconds(10000));
    EXPECT_EQ(Status(job).state(), pb::STATE_INGESTING);
  }  // gone without an end
  pb::JobStatus s;
  for (int i = 0; i < 100 && s.state() != pb::STATE_FAILED; ++i) {
    std::this_thread::sleep_for(milliseconds(100));
    s = Status(job);
  }
  EXPECT_EQ(s.state(), pb::STATE_FAILED);
  EXPECT_NE(s.message().find("client gone"), std::string::npos) << s.message();
  EXPECT_EQ(s.frames_spooled(), 3u);
  StreamClient late(context_, ing_);
  pb::Envelope env = NewEnvelope(job);
  *env.mutable_stream_frame()->mutable_frame() = frames[3];
  late.SendUnchecked(env);
  auto r = late.Receive(milliseconds(5000));
  ASSERT_TRUE(r.has_value());
  EXPECT_TRUE(r->has_error());
  // `lfrecon stream` against a dead ingest fails, naming the endpoint, instead of waiting for ever.
  procs_[1]->Kill(SIGKILL);
  const auto cli = RunShell(kBin + "lfrecon -q stream --ingest " + ing_ + " --aggregate " + agg_ + " --dataset " +
                            data.string() + " --timeout-ms 1500");
  EXPECT_EQ(cli.code, 1) << cli.output;
  EXPECT_NE(cli.output.find("no answer"), std::string::npos) << cli.output;
}

}  // namespace
}  // namespace lfrecon::svc
