#include "sfm/colmap_poses.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <random>

#include "common/test_util.h"
#include "io/dataset.h"
#include "sfm/subprocess.h"
#include "sfm/video_writer.h"
#include "sfm/world_frame.h"
#include "synth/sequence.h"
#include "util/error.h"

namespace lfrecon {
namespace {

namespace fs = std::filesystem;
using testing::TempDir;

std::string Message(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "";
}

TEST(Subprocess, MissingBinaryIsNamed) {
  const std::string m = Message([] { RunSubprocess({"lfrecon-no-such-tool", "x"}); });
  EXPECT_NE(m.find("lfrecon-no-such-tool"), std::string::npos) << m;
  EXPECT_NE(m.find("not found"), std::string::npos) << m;
}

TEST(Subprocess, ExitStatusAndLastLines) {
  std::vector<std::string> seen;
  SubprocessOptions o;
  o.keep_lines = 2;
  o.on_line = [&](const std::string& l, bool) { seen.push_back(l); };
  // An argv array, no shell string: the script is one argument of /bin/sh.
  const SubprocessResult r =
      RunSubprocess({"/bin/sh", "-c", "echo one; echo two >&2; printf 'three\\nfour'; exit 3"}, o);
  EXPECT_EQ(r.exit_status, 3);
  EXPECT_FALSE(r.signaled);
  ASSERT_EQ(seen.size(), 4u);
  ASSERT_EQ(r.last_lines.size(), 2u);
  EXPECT_EQ(r.last_lines.back(), "four");
}

TEST(ColmapPoses, MissingColmapIsAClearError) {
  TempDir dir;
  ColmapPosesOptions o;
  o.images_dir = dir.path();
  o.out_dir = dir.path() / "out";
  o.colmap = (dir.path() / "bin" / "colmap").string();
  const std::string m = Message([&] { EstimatePosesWithColmap(o); });
  EXPECT_NE(m.find("COLMAP"), std::string::npos) << m;
  EXPECT_NE(m.find(o.colmap), std::string::npos) << m;
  EXPECT_NE(m.find("apt-get install colmap"), std::string::npos) << m;
}

TEST(ColmapPoses, FailingStepNamesBinaryStatusAndStderr) {
  TempDir dir;
  // A stand-in for colmap that fails the way a real step does.
  const fs::path fake = dir.path() / "fake-colmap";
  {
    std::ofstream f(fake);
    f << "#!/bin/sh\necho \"F1202 feature_extractor: Check failed: camera model ($1)\" >&2\nexit 4\n";
  }
  fs::permissions(fake, fs::perms::owner_all);
  fs::create_directories(dir.path() / "in");
  for (int i = 0; i < 4; ++i) {
    cv::Mat img(16, 16, CV_8UC3, cv::Scalar(i, i, i));
    cv::imwrite((dir.path() / "in" / ("f" + std::to_string(i) + ".png")).string(), img);
  }
  ColmapPosesOptions o;
  o.images_dir = dir.path() / "in";
  o.out_dir = dir.path() / "out";
  o.colmap = fake.string();
  const std::string m = Message([&] { EstimatePosesWithColmap(o); });
  EXPECT_NE(m.find(fake.string() + " feature_extractor failed (exit status 4)"), std::string::npos) << m;
  EXPECT_NE(m.find("Check failed: camera model (feature_extractor)"), std::string::npos) << m;
}

// A relative --out, as a user types it: COLMAP runs in OUT/colmap, so the
// paths it is given must be absolute (they were relative, and COLMAP refused
// the database path). The stand-in says which it got.
TEST(ColmapPoses, RelativeOutputFolderReachesColmapAsAbsolutePaths) {
  TempDir dir;
  const fs::path fake = dir.path() / "fake-colmap";
  {
    std::ofstream f(fake);
    f << "#!/bin/sh\nprev=\n"
         "for a in \"$@\"; do\n"
         "  if [ \"$prev\" = --database_path ]; then\n"
         "    case \"$a\" in /*) echo \"absolute database path\" >&2; exit 4;; esac\n"
         "    echo \"relative database path $a\" >&2; exit 5\n"
         "  fi\n"
         "  prev=$a\n"
         "done\nexit 6\n";
  }
  fs::permissions(fake, fs::perms::owner_all);
  fs::create_directories(dir.path() / "in");
  for (int i = 0; i < 4; ++i) {
    const cv::Mat img(16, 16, CV_8UC3, cv::Scalar(i, i, i));
    cv::imwrite((dir.path() / "in" / ("f" + std::to_string(i) + ".png")).string(), img);
  }
  ColmapPosesOptions o;
  o.images_dir = "in";
  o.out_dir = "out";
  o.colmap = fake.string();
  const fs::path cwd = fs::current_path();
  fs::current_path(dir.path());
  const std::string m = Message([&] { EstimatePosesWithColmap(o); });
  fs::current_path(cwd);
  EXPECT_NE(m.find("absolute database path"), std::string::npos) << m;
  EXPECT_NE(m.find("exit status 4"), std::string::npos) << m;
  EXPECT_TRUE(fs::is_directory(dir.path() / "out" / "colmap" / "logs")) << "OUT resolved against the caller's folder";
}

TEST(ColmapPoses, OptionsAreChecked) {
  ColmapPosesOptions o;
  o.out_dir = "/tmp/x";
  EXPECT_THROW(o.Check(), OptionError);  // neither --video nor --images
  o.video_path = "v.mkv";
  o.step = -1;
  EXPECT_THROW(o.Check(), OptionError);
  o.step = 0;  // automatic
  EXPECT_NO_THROW(o.Check());
  o.max_keyframes = 2;
  EXPECT_THROW(o.Check(), OptionError);
  o.max_keyframes = 160;
  o.step = 3;
  o.camera_model = "OPENCV";
  EXPECT_THROW(o.Check(), OptionError);
  o.camera_model = "PINHOLE";
  EXPECT_NO_THROW(o.Check());
}

TEST(ColmapPoses, AutomaticStepBoundsTheKeyframes) {
  EXPECT_EQ(KeyframeStep(48, 160), 3);
  EXPECT_EQ(KeyframeStep(480, 160), 3);
  EXPECT_EQ(KeyframeStep(481, 160), 4);
  EXPECT_EQ(KeyframeStep(3000, 160), 19);
  EXPECT_EQ(KeyframeStep(100000, 160), 625);
  for (int frames : {10, 480, 481, 1000, 3000, 12345})
    EXPECT_LE((frames + KeyframeStep(frames, 160) - 1) / KeyframeStep(frames, 160), 160) << frames;
}

// Cameras on a ring looking at a box of points, in a world with another up,
// origin and scale; a few distractors (a far wall) around.
struct RingScene {
  std::vector<Rigid3d> poses;
  std::vector<Camera> cameras;
  std::vector<SparsePoint> points;
  BoundingBox box;
};

RingScene MakeRing(const Similarity3d& world_to_sfm) {
  RingScene s;
  s.box.min = Eigen::Vector3d(-0.2, -0.15, 0.0);
  s.box.max = Eigen::Vector3d(0.2, 0.15, 0.3);
  const Camera cam = Camera::PinholeFromHfov(320, 180, 55);
  for (int i = 0; i < 72; ++i) {
    const double a = 2 * M_PI * i / 72;
    const Eigen::Vector3d eye(0.9 * std::cos(a), 0.9 * std::sin(a), 0.7);
    s.poses.push_back(world_to_sfm.TransformPose(LookAt(eye, Eigen::Vector3d(0, 0, 0.15), Eigen::Vector3d::UnitZ())));
    s.cameras.push_back(cam);
  }
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0, 1);
  auto add = [&](const Eigen::Vector3d& p) {
    SparsePoint sp;
    sp.xyz = world_to_sfm * p;
    sp.error = 0.5;
    sp.image_ids = {1, 2, 3, 4};
    s.points.push_back(sp);
  };
  for (int k = 0; k < 3000; ++k)
    add(s.box.min + (s.box.max - s.box.min).cwiseProduct(Eigen::Vector3d(u(rng), u(rng), u(rng))));
  for (int k = 0; k < 400; ++k) {  // a wall behind the ring
    const double a = 2 * M_PI * u(rng);
    add(Eigen::Vector3d(3 * std::cos(a), 3 * std::sin(a), 2 * u(rng)));
  }
  return s;
}

double cam_focal(const Camera& c) { return c.fy(); }

TEST(WorldFrame, UpVolumeAndScaleFromARing) {
  Similarity3d world_to_sfm;
  world_to_sfm.scale = 7.3;
  world_to_sfm.rotation = Eigen::AngleAxisd(1.1, Eigen::Vector3d(0.3, -0.8, 0.5).normalized()).toRotationMatrix();
  world_to_sfm.translation = Eigen::Vector3d(2, -1, 4);
  const RingScene s = MakeRing(world_to_sfm);
  WorldFrameOptions o;
  o.camera_distance = 1.0;
  o.padding = 0;
  o.percentile = 0;
  const WorldFrame f = EstimateWorldFrame(s.poses, s.cameras, s.points, o);
  // Up: the true world's +z.
  const Eigen::Vector3d up_true = world_to_sfm.rotation * Eigen::Vector3d::UnitZ();
  EXPECT_LT(std::acos(std::min(1.0, f.up_sfm.dot(up_true))) * 180 / M_PI, 0.01);
  // The wall is left out; the box keeps its shape (scaled; rotated about z at most).
  EXPECT_GE(f.points_in_volume, 2850);
  EXPECT_LE(f.points_in_volume, 3000);
  std::vector<double> d;
  for (const Rigid3d& p : s.poses) {
    const Eigen::Vector3d c = f.sfm_to_world * CameraCenter(p);
    d.push_back((c - f.volume.Center()).norm());
  }
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  EXPECT_NEAR(d[d.size() / 2], 1.0, 1e-9);
  const double scale = f.sfm_to_world.scale * world_to_sfm.scale;  // true metres -> written units
  // Its top: where the views' upper image edge meets the vertical axis through
  // V's centre (above the points' top, 0.3 m, which thin tall things would exceed).
  const double f_px = cam_focal(s.cameras[0]);
  const double top = 0.7 - 0.9 * std::tan(std::atan(0.55 / 0.9) - std::atan(90.0 / f_px));
  EXPECT_NEAR(f.volume.Extent().z(), scale * top, scale * 0.01);
  EXPECT_GT(top, 0.3);
  EXPECT_NEAR(f.volume.min.z(), 0.0, 1e-9);  // origin at V's bottom centre
  EXPECT_NEAR(f.volume.Center().x(), 0.0, 1e-9);
  // Horizontal extent between the box's sides and its diagonal (unknown rotation about up).
  const double h = std::max(f.volume.Extent().x(), f.volume.Extent().y());
  EXPECT_GE(h, scale * 0.4 * 0.99);
  EXPECT_LE(h, scale * 0.5 * 1.01);
}

TEST(WorldFrame, AlignCamerasRecoversASimilarity) {
  Similarity3d S;
  S.scale = 0.37;
  S.rotation = Eigen::AngleAxisd(-0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  S.translation = Eigen::Vector3d(0.1, 0.2, -0.3);
  const RingScene truth = MakeRing(Similarity3d());
  std::vector<Rigid3d> est;
  for (const Rigid3d& p : truth.poses) est.push_back(S.TransformPose(p));
  const Similarity3d A = AlignCameras(est, truth.poses);
  const PoseErrors e = ComparePoses(est, truth.poses, A, Eigen::Vector3d(0, 0, 0.15));
  EXPECT_LT(e.max_rotation_deg, 1e-6);
  EXPECT_LT(e.max_center, 1e-9);
  EXPECT_NEAR(e.camera_distance, std::hypot(0.9, 0.55), 1e-9);
  EXPECT_NEAR(A.scale * S.scale, 1.0, 1e-9);
}

TEST(WorldFrame, ReadsPoints3DText) {
  TempDir dir;
  {
    std::ofstream f(dir.path() / "points3D.txt");
    f << "# header\n1 0.5 -1 2 10 20 30 0.25 1 0 2 5 7 1\n";
  }
  const std::vector<SparsePoint> p = ReadColmapPoints3D(dir.path());
  ASSERT_EQ(p.size(), 1u);
  EXPECT_EQ(p[0].xyz, Eigen::Vector3d(0.5, -1, 2));
  EXPECT_EQ(p[0].image_ids, (std::vector<std::uint32_t>{1, 2, 7}));
  EXPECT_DOUBLE_EQ(p[0].error, 0.25);
  {
    std::ofstream f(dir.path() / "points3D.txt");
    f << "1 0.5 nope\n";
  }
  testing::ExpectInputError([&] { ReadColmapPoints3D(dir.path()); }, {"points3D.txt", "line 1"});
}

// Issue 17: a generated loop rendered to a video file and posed by COLMAP:
// after a similarity alignment to the true cameras, median rotation error
// <= 0.15 deg and centre error <= 0.3 % of the camera distance. 480x270: at
// 320x180 the same loop gave 0.07-0.12 deg over runs (COLMAP's threads make
// runs differ; the error is a smooth deformation of the ring, not noise).
// 24 frames 15 deg apart, every 2nd a keyframe (13, 30 deg apart) and 11
// registered to them: 0.074-0.081 deg and 0.07-0.12 % over 4 runs, ~25 CPU-s
// (48 frames, every 3rd a keyframe: 0.053-0.058 deg and 0.10 %, ~53 CPU-s; on
// CPU each frame costs ~0.6 CPU-s of SIFT, whose first octave doubles it, and
// each matched pair ~0.13 CPU-s; fewer features or a half loop fail the bounds
// or the V checks).
TEST(ColmapPoses, GeneratedLoopVideo) {
  if (FindExecutable("colmap").empty()) GTEST_SKIP() << "colmap is not installed (apt-get install colmap): skipped";
  TempDir dir;
  synth::SynthOptions so;
  so.scene = "tabletop";
  so.frames = 24;
  so.width = 480;
  so.height = 270;
  so.render.quantize = true;
  const synth::SynthSequence seq = synth::SynthSequence::Create(so);
  std::string codec;
  const fs::path video = testing::WriteVideo(dir.path() / "loop", seq.NumFrames(), 30, [&](int i) {
    cv::Mat u8;
    seq.RenderImage(i).convertTo(u8, CV_8UC3, 255.0);
    return u8;
  }, &codec);
  std::printf("video: %s (%s)\n", video.c_str(), codec.c_str());

  ColmapPosesOptions o;
  o.video_path = video;
  o.out_dir = dir.path() / "posed";
  o.step = 2;
  o.max_num_features = 1024;
  o.overlap = 3;
  o.loop_pairs = 2;
  o.register_neighbours = 1;
  const ColmapPosesSummary s = EstimatePosesWithColmap(o);
  std::printf("poses: %d/%d frames, %d/%d keyframes in %.1f s\n", s.registered, s.frames, s.keyframes_registered,
              s.keyframes, s.seconds);
  for (const auto& [name, sec] : s.step_seconds) std::printf("  %s: %.1f s\n", name.c_str(), sec);
  EXPECT_EQ(s.frames, 24);
  EXPECT_EQ(s.keyframes, 13);
  EXPECT_EQ(s.registered, 24);

  // The written dataset opens as lfrecon run opens it, V from its scene.json.
  DatasetOptions dopt;
  dopt.dataset_dir = o.out_dir;
  const Dataset ds = Dataset::Open(dopt);
  EXPECT_EQ(ds.bbox_source(), "scene.json");
  ASSERT_EQ(ds.NumViews(), s.registered);
  std::vector<Rigid3d> est, truth;
  for (const DatasetView& v : ds.views()) {
    est.push_back(v.cam_from_world);
    const int frame = std::stoi(v.name.substr(6, 5));  // frame_NNNNN.png
    truth.push_back(seq.cam_from_world(frame));
  }
  const BoundingBox& V_true = seq.scene().foreground_bbox();
  const Similarity3d A = AlignCameras(est, truth);
  const PoseErrors e = ComparePoses(est, truth, A, V_true.Center());
  std::printf("median rotation error %.4f deg (max %.4f), centre error %.4f %% of the camera distance (max %.4f %%)\n",
              e.median_rotation_deg, e.max_rotation_deg, 100 * e.median_center_relative(),
              100 * e.max_center_relative());
  // COLMAP 3.8 seeds the RANSAC of its worker threads from the clock, so these vary from run to
  // run: 0.068-0.105 deg and 0.05-0.18 % over ten runs (was <= 0.1 deg / 0.2 %, which a loaded
  // clean-clone run failed at 0.105 deg); the bounds leave room for that spread.
  EXPECT_LE(e.median_rotation_deg, 0.15);
  EXPECT_LE(e.median_center_relative(), 0.003);

  // Up is +z and V, mapped into the true world, covers the true V's centre and is of its size.
  const Eigen::Vector3d up = A.rotation * Eigen::Vector3d::UnitZ();
  EXPECT_GT(up.z(), std::cos(2.0 * M_PI / 180));
  const Eigen::Vector3d c = A * ds.bbox().Center();
  EXPECT_LT((c - V_true.Center()).norm(), 0.25 * V_true.Extent().norm()) << c.transpose();
  const double ratio = A.scale * ds.bbox().Extent().maxCoeff() / V_true.Extent().maxCoeff();
  EXPECT_GT(ratio, 0.6);
  EXPECT_LT(ratio, 1.6);
}

}  // namespace
}  // namespace lfrecon
