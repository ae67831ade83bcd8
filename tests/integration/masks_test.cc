// Object masks in the service (Frame.mask, proto/lfrecon_service.proto): a
// generated scene with masks (`lfrecon synth --masks`, scene.json removed so
// that V is the masks' visual hull) submitted to the service, and streamed to
// it (also with --masks DIR), gives lfrecon run's fused mesh with the masks'
// free space, vertex for vertex, and its count of masked views; without the
// masks' free space the mesh differs (so the comparison can fail). A job with
// --mask-carving gives lfrecon run --mask-carving's refined mesh, one without
// it run's default one. The manifest records whether the frames carry masks
// (JobManifest.frame_masks). A mask of the wrong size, or one that is not PNG,
// is refused at ingest with an error naming the frame.
// Real daemons over ipc:// in a temporary folder.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "common/job_store.h"
#include "common/messaging.h"
#include "common/stream_client.h"
#include "common/test_util.h"
#include "io/dataset.h"
#include "io/ply.h"
#include "service_stack.h"

namespace lfrecon::svc {
namespace {
namespace fs = std::filesystem;
using lfrecon::testing::kBin;
using lfrecon::testing::ServiceStackTest;
using lfrecon::testing::Sh;
using std::chrono::milliseconds;

constexpr double kVoxelMm = 6.0;

std::string FirstLine(const std::string& s) { return s.substr(0, s.find('\n')); }

// The largest distance between corresponding vertices; infinity when the meshes differ in size.
double LargestDifference(const TriangleMesh& a, const TriangleMesh& b) {
  if (a.vertices.size() != b.vertices.size() || a.triangles.size() != b.triangles.size())
    return std::numeric_limits<double>::infinity();
  double d = 0;
  for (std::size_t k = 0; k < a.vertices.size(); ++k)
    d = std::max(d, static_cast<double>((a.vertices[k] - b.vertices[k]).norm()));
  return d;
}

class MasksTest : public ServiceStackTest {
 protected:
  // A generated arc with masks (JPEG frames, PNG masks in masks/), without
  // scene.json: V is the masks' visual hull, in lfrecon run and in the service.
  fs::path Synth(int frames, int width, int height, double degrees) {
    const fs::path data = tmp_.path() / "dataset";
    Sh(kBin + "lfrecon -q synth --scene sphere --masks --frames " + std::to_string(frames) + " --loops " +
       std::to_string(degrees / 360.0) + " --width " + std::to_string(width) + " --height " +
       std::to_string(height) + " --depth-every 0 --no-meshes --format jpg --out " + data.string());
    fs::remove(data / "scene.json");
    return data;
  }
};

// `lfrecon submit` and `lfrecon stream` of a masked dataset: every frame in the
// job store carries its mask as lfrecon run reads it, V is the masks' hull, and
// the fused mesh is lfrecon run's (masks as free space, the default), not the
// one without the masks' free space.
TEST_F(MasksTest, SubmitAndStreamOfMaskedDatasetEqualRun) {
  constexpr int kFrames = 24;
  const fs::path data = Synth(kFrames, 120, 68, 24.0);
  DatasetOptions d;
  d.dataset_dir = data;
  const Dataset ds = Dataset::Open(d);
  ASSERT_TRUE(ds.HasMasks());
  EXPECT_EQ(ds.bbox_source().rfind("masks", 0), 0u) << ds.bbox_source();
  const std::string voxel = " --voxel-mm " + std::to_string(kVoxelMm);
  const fs::path run_dir = tmp_.path() / "run", plain_dir = tmp_.path() / "run_plain";
  Sh(kBin + "lfrecon -q run --dataset " + data.string() + " --no-refine-poses" + voxel + " --out " + run_dir.string());
  Sh(kBin + "lfrecon -q run --dataset " + data.string() + " --no-refine-poses --no-refine --no-mask-free-space" +
     voxel + " --out " + plain_dir.string());
  const nlohmann::json report = nlohmann::json::parse(ReadFileBytes(run_dir / "report.json"));
  const int selected = report["views"]["processed"];
  const int masked = report["counts"]["masked_views"];
  EXPECT_GT(selected, 0);
  EXPECT_EQ(masked, selected);  // every processed view has a mask
  const TriangleMesh run_mesh = ReadPly(run_dir / "mesh_raw.ply");
  const TriangleMesh plain_mesh = ReadPly(plain_dir / "mesh_raw.ply");
  ASSERT_GT(run_mesh.triangles.size(), 100u);
  // The masks' free space changes the mesh: a service that ignored the masks would not match it.
  EXPECT_GT(LargestDifference(run_mesh, plain_mesh), 0.0);

  StartStack(1);
  JobStore js(store_);
  auto check_job = [&](const std::string& how, const std::string& job) {
    const pb::JobStatus s = Status(job);
    EXPECT_EQ(s.state(), pb::STATE_DONE) << how << ": " << s.message();
    EXPECT_EQ(s.views_fused(), static_cast<unsigned>(selected)) << how;
    EXPECT_EQ(s.masked_views(), static_cast<unsigned>(masked)) << how;
    const pb::JobManifest m = js.ReadManifest(job);
    EXPECT_TRUE(m.has_frame_masks() && m.frame_masks()) << how << ": the manifest says the frames carry masks";
    const BoundingBox v = BoxFromProto(m.volume(), how);
    EXPECT_EQ((v.min - ds.bbox().min).norm() + (v.max - ds.bbox().max).norm(), 0.0) << how << ": V from the masks";
    int frames_with_masks = 0;
    for (int k = 0; k < kFrames; ++k) {
      const cv::Mat stored = js.ReadMask(job, k, ds.View(k));
      const cv::Mat read = ds.ReadMask(k);
      frames_with_masks += !stored.empty();
      EXPECT_TRUE(!stored.empty() && cv::norm(stored, read, cv::NORM_INF) == 0) << how << ": mask of frame " << k;
    }
    const TriangleMesh mesh = ReadPly(store_ / job / "mesh_raw.ply");
    const double dv = LargestDifference(mesh, run_mesh);
    EXPECT_EQ(dv, 0.0) << how;
    std::printf("%s: %d/%d frames stored with their mask, %u/%u views fused with it (lfrecon run: %d); mesh_raw %zu "
                "triangles, largest vertex difference to lfrecon run's (%zu triangles) %.3g m; run "
                "--no-mask-free-space: %zu triangles\n",
                how.c_str(), frames_with_masks, kFrames, s.masked_views(), s.views_fused(), masked,
                mesh.triangles.size(), run_mesh.triangles.size(), dv, plain_mesh.triangles.size());
  };
  const std::string submitted = FirstLine(Sh(kBin + "lfrecon -q submit --ingest " + ing_ + " --aggregate " + agg_ +
                                             " --dataset " + data.string() + voxel + " --wait --wait-s 300"));
  ASSERT_TRUE(JobStore::ValidJobId(submitted)) << submitted;
  EXPECT_EQ(js.ReadManifest(submitted).bbox_source().rfind("masks", 0), 0u) << js.ReadManifest(submitted).bbox_source();
  check_job("submit", submitted);
  // export --refine rebuilds the grid from the stored maps with the same masks' free space: lfrecon run's
  // mesh.ply up to the float rounding of another fusion order (not run --no-mask-free-space's).
  const fs::path refined = tmp_.path() / "refined.ply";
  Sh(kBin + "lfrecon -q export " + submitted + " --refine --aggregate " + agg_ + " -o " + refined.string());
  const std::size_t refined_triangles = ReadPly(refined).triangles.size();
  const std::size_t run_refined = ReadPly(run_dir / "mesh.ply").triangles.size();
  EXPECT_NEAR(static_cast<double>(refined_triangles), static_cast<double>(run_refined), 0.01 * run_refined);
  std::printf("export --refine: %zu triangles (lfrecon run mesh.ply: %zu)\n", refined_triangles, run_refined);
  // --mask-carving: the refined export also carves outside the frames' masks, as lfrecon run --mask-carving;
  // the fusion (mesh_raw) is unchanged. run --mask-carving carves voxels outside the masks, so its mesh.ply
  // differs from run's, and the job without the option keeps run's.
  const fs::path run_mc_dir = tmp_.path() / "run_mask_carving";
  Sh(kBin + "lfrecon -q run --dataset " + data.string() + " --no-refine-poses --mask-carving" + voxel + " --out " +
     run_mc_dir.string());
  const nlohmann::json mc_report = nlohmann::json::parse(ReadFileBytes(run_mc_dir / "report.json"));
  const int carved_outside = mc_report["counts"]["carved_outside_masks"];
  EXPECT_GT(carved_outside, 0);
  EXPECT_EQ(mc_report["counts"]["carving_mask_views"], report["counts"]["carving_frames"]);
  EXPECT_EQ(report["counts"]["carved_outside_masks"], 0);
  const TriangleMesh run_refined_mesh = ReadPly(run_dir / "mesh.ply");
  const TriangleMesh run_mc_mesh = ReadPly(run_mc_dir / "mesh.ply");
  EXPECT_NE(run_mc_mesh.triangles.size(), run_refined_mesh.triangles.size());
  const std::string carving = FirstLine(Sh(kBin + "lfrecon -q submit --ingest " + ing_ + " --aggregate " + agg_ +
                                           " --dataset " + data.string() + voxel +
                                           " --mask-carving --wait --wait-s 300"));
  ASSERT_TRUE(JobStore::ValidJobId(carving)) << carving;
  EXPECT_TRUE(js.ReadManifest(carving).spec().options().mask_carving());
  check_job("submit --mask-carving", carving);
  const fs::path refined_mc = tmp_.path() / "refined_mask_carving.ply";
  Sh(kBin + "lfrecon -q export " + carving + " --refine --aggregate " + agg_ + " -o " + refined_mc.string());
  const TriangleMesh refined_mc_mesh = ReadPly(refined_mc), refined_mesh = ReadPly(refined);
  // Vertex for vertex: the same grid (view order), the same carving frames and masks, the same carving.
  const double d_mc = LargestDifference(refined_mc_mesh, run_mc_mesh);
  const double d_plain = LargestDifference(refined_mesh, run_refined_mesh);
  EXPECT_LE(d_mc, 1e-6) << "export --refine of a --mask-carving job against run --mask-carving's mesh.ply";
  EXPECT_LE(d_plain, 1e-6) << "export --refine of a job without it against run's mesh.ply";
  EXPECT_EQ(LargestDifference(refined_mc_mesh, run_refined_mesh), std::numeric_limits<double>::infinity());
  std::printf("export --refine --mask-carving job: %zu triangles, largest vertex difference to run --mask-carving's "
              "mesh.ply (%zu triangles, %d voxels carved outside the masks) %.3g m; without the option %zu "
              "triangles, %.3g m to run's (%zu)\n",
              refined_mc_mesh.triangles.size(), run_mc_mesh.triangles.size(), carved_outside, d_mc,
              refined_mesh.triangles.size(), d_plain, run_refined_mesh.triangles.size());
  const std::string streamed = FirstLine(Sh(kBin + "lfrecon -q stream --ingest " + ing_ + " --aggregate " + agg_ +
                                            " --dataset " + data.string() + voxel + " --wait --wait-s 300"));
  ASSERT_TRUE(JobStore::ValidJobId(streamed)) << streamed;
  check_job("stream", streamed);
  // --no-mask-free-space: the masks give V only, as lfrecon run --no-mask-free-space.
  const std::string plain = FirstLine(Sh(kBin + "lfrecon -q submit --ingest " + ing_ + " --aggregate " + agg_ +
                                         " --dataset " + data.string() + voxel +
                                         " --no-mask-free-space --wait --wait-s 300"));
  ASSERT_TRUE(JobStore::ValidJobId(plain)) << plain;
  EXPECT_EQ(Status(plain).masked_views(), 0u);
  EXPECT_EQ(LargestDifference(ReadPly(store_ / plain / "mesh_raw.ply"), plain_mesh), 0.0);
  // Masks from another folder (--masks DIR, sent as JobSpec.masks_dir): the same job.
  fs::rename(data / "masks", tmp_.path() / "masks_elsewhere");
  const std::string elsewhere = FirstLine(Sh(kBin + "lfrecon -q submit --ingest " + ing_ + " --aggregate " + agg_ +
                                             " --dataset " + data.string() + " --masks " +
                                             (tmp_.path() / "masks_elsewhere").string() + voxel + " --wait --wait-s 300"));
  ASSERT_TRUE(JobStore::ValidJobId(elsewhere)) << elsewhere;
  EXPECT_EQ(Status(elsewhere).masked_views(), static_cast<unsigned>(masked));
  EXPECT_EQ(LargestDifference(ReadPly(store_ / elsewhere / "mesh_raw.ply"), run_mesh), 0.0) << "submit --masks";
}

// A pushed frame whose mask does not fit its camera, or is not PNG, is refused
// (ERROR_INPUT naming the frame and its mask; not stored, so the stream goes
// on), before any pixel of it is decoded; the whole frame is then stored with its mask.
TEST_F(MasksTest, MalformedMaskIsRefusedNamingTheFrame) {
  const fs::path data = Synth(4, 64, 36, 4.0);
  DatasetOptions d;
  d.dataset_dir = data;
  const Dataset ds = Dataset::Open(d);
  StoreFrameEncoder enc(ds);
  std::vector<pb::Frame> frames;
  for (int k = 0; k < ds.NumViews(); ++k) frames.push_back(enc.Encode(k, false));
  ASSERT_FALSE(frames[2].mask().empty());
  StartStack(0);
  StreamClient client(context_, ing_);
  pb::StreamOpen open;
  for (int k = 0; k < 3; ++k) open.mutable_spec()->add_bbox(ds.bbox().min(k));
  for (int k = 0; k < 3; ++k) open.mutable_spec()->add_bbox(ds.bbox().max(k));
  client.Open(open, milliseconds(10000));
  auto refusal = [&](const pb::Frame& f) -> std::string {  // the answer to one frame
    pb::Envelope env = NewEnvelope();
    *env.mutable_stream_frame()->mutable_frame() = f;
    client.SendUnchecked(env);
    const auto r = client.Receive(milliseconds(10000));
    if (!r) return "(no answer)";
    if (!r->has_error()) return "(stored)";
    EXPECT_EQ(r->error().code(), pb::ERROR_INPUT) << r->error().message();
    return r->error().message();
  };
  // A mask of another size: its PNG header is 32x36 (a huge one would be refused the same way, undecoded).
  pb::Frame wrong_size = frames[2];
  std::vector<uchar> png;
  cv::imencode(".png", cv::Mat(36, 32, CV_8U, cv::Scalar(255)), png);
  wrong_size.set_mask(std::string(png.begin(), png.end()));
  std::string why = refusal(wrong_size);
  EXPECT_NE(why.find("frame 2"), std::string::npos) << why;
  EXPECT_NE(why.find("mask is 32x36, its frame 64x36"), std::string::npos) << why;
  // A mask with three channels (a colour PNG of the right size).
  pb::Frame colour = frames[2];
  png.clear();
  cv::imencode(".png", cv::Mat(36, 64, CV_8UC3, cv::Scalar(255, 255, 255)), png);
  colour.set_mask(std::string(png.begin(), png.end()));
  why = refusal(colour);
  EXPECT_NE(why.find("frame 2"), std::string::npos) << why;
  EXPECT_NE(why.find("one channel"), std::string::npos) << why;
  // Bytes that are not PNG (here the frame's own JPEG).
  pb::Frame not_png = frames[1];
  not_png.set_mask(frames[1].data());
  why = refusal(not_png);
  EXPECT_NE(why.find("frame 1"), std::string::npos) << why;
  EXPECT_NE(why.find("mask"), std::string::npos) << why;
  EXPECT_NE(why.find("not PNG"), std::string::npos) << why;
  // The refused indices are pushed again, whole: stored with their masks, the stream ends.
  for (const pb::Frame& f : frames) client.Push(f, milliseconds(10000));
  EXPECT_EQ(client.End(static_cast<std::uint32_t>(frames.size()), milliseconds(30000)).num_frames(), frames.size());
  JobStore js(store_);
  for (int k = 0; k < ds.NumViews(); ++k)
    EXPECT_EQ(cv::norm(js.ReadMask(client.job_id(), k, ds.View(k)), ds.ReadMask(k), cv::NORM_INF), 0) << k;
}

// The manifest records whether the job's frames carry masks (JobManifest.frame_masks), so the
// aggregator reads no frame file for a mask when none does (JobGeometry::frame_masks): a submitted
// masked dataset says so before its first frame, a stream after its end (the frames it stored);
// an open stream's geometry knows it from its stored frames; a manifest without the field (a store
// written before it) means "look at each frame".
TEST_F(MasksTest, ManifestRecordsWhetherFramesCarryMasks) {
  const fs::path data = Synth(4, 64, 36, 4.0);
  DatasetOptions d;
  d.dataset_dir = data;
  const Dataset ds = Dataset::Open(d);
  StoreFrameEncoder enc(ds);
  StartStack(0);
  JobStore js(store_);
  const std::string submitted =
      FirstLine(Sh(kBin + "lfrecon -q submit --ingest " + ing_ + " --aggregate " + agg_ + " --dataset " + data.string()));
  ASSERT_TRUE(JobStore::ValidJobId(submitted)) << submitted;
  const pb::JobManifest sm = js.ReadManifest(submitted);  // written before the reply
  EXPECT_TRUE(sm.has_frame_masks() && sm.frame_masks());
  EXPECT_TRUE(LoadJobGeometry(js, submitted).frame_masks);
  // A stream of the same frames with and without their masks; V given, so it is a job while open.
  auto stream = [&](bool masks) {
    StreamClient client(context_, ing_);
    pb::StreamOpen open;
    for (int k = 0; k < 3; ++k) open.mutable_spec()->add_bbox(ds.bbox().min(k));
    for (int k = 0; k < 3; ++k) open.mutable_spec()->add_bbox(ds.bbox().max(k));
    client.Open(open, milliseconds(10000));
    for (int k = 0; k < ds.NumViews(); ++k) {
      pb::Frame f = enc.Encode(k, false);
      EXPECT_FALSE(f.mask().empty());
      if (!masks) f.clear_mask();
      if (k > 0) {
        client.Push(f, milliseconds(10000));
        continue;
      }
      pb::Envelope env = NewEnvelope();  // the first frame, answered once stored
      *env.mutable_stream_frame()->mutable_frame() = f;
      client.SendUnchecked(env);
      const auto r = client.Receive(milliseconds(10000));
      EXPECT_TRUE(r && !r->has_error()) << (r ? r->error().message() : "(no answer)");
      const JobGeometry open_geo = LoadStreamGeometry(js, client.job_id());
      EXPECT_EQ(open_geo.views.size(), 1u);
      EXPECT_EQ(open_geo.frame_masks, masks) << "open stream, masks " << masks;
    }
    client.End(static_cast<std::uint32_t>(ds.NumViews()), milliseconds(30000));
    const pb::JobManifest m = js.ReadManifest(client.job_id());
    EXPECT_TRUE(m.has_frame_masks());
    EXPECT_EQ(m.frame_masks(), masks);
    EXPECT_EQ(LoadJobGeometry(js, client.job_id()).frame_masks, masks) << "ended stream, masks " << masks;
    return client.job_id();
  };
  stream(true);
  const std::string plain = stream(false);
  // A manifest without the field: unknown, so each frame is looked at.
  pb::JobManifest old = js.ReadManifest(plain);
  old.clear_frame_masks();
  js.WriteManifest(old);
  EXPECT_TRUE(LoadJobGeometry(js, plain).frame_masks);
}

}  // namespace
}  // namespace lfrecon::svc
