#include "io/dataset.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <fstream>
#include <functional>
#include <limits>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "geometry/undistorter.h"
#include "io/colmap_model.h"
#include "io/depth_map_io.h"
#include "io/transforms_json.h"
#include "util/error.h"
#include "common/test_util.h"

namespace lfrecon {
namespace {

using testing::TempDir;
using testing::ExpectInputError;
namespace fs = std::filesystem;

const Eigen::Vector3d kTarget(0.1, -0.2, 0.3);

// A ring of cameras around kTarget, unpadded names (natural order matters), 64x48 PNGs.
struct Synthetic {
  ColmapModel model;
  std::vector<std::string> names;  // in natural order
};

Synthetic MakeSynthetic(int n, const Camera& camera) {
  Synthetic s;
  s.model.cameras[1] = camera;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * M_PI * i / n;
    const Eigen::Vector3d eye = kTarget + Eigen::Vector3d(2 * std::cos(a), 2 * std::sin(a), 1.0);
    ColmapImage image;
    image.image_id = i + 1;
    image.camera_id = 1;
    image.name = "frame_" + std::to_string(i + 1) + ".png";
    image.cam_from_world = LookAt(eye, kTarget, Eigen::Vector3d::UnitZ());
    s.model.images.push_back(image);
    s.names.push_back(image.name);
  }
  return s;
}

cv::Mat Pattern(int i, int rows, int cols) {
  cv::Mat m(rows, cols, CV_8UC3);
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c)
      m.at<cv::Vec3b>(r, c) =
          cv::Vec3b((c * 16) % 256, (r * 16) % 256, (i * 20 + (r / 8 + c / 8) % 2 * 100) % 256);
  return m;
}

void WriteImages(const Synthetic& s, const fs::path& dir) {
  const Camera& c = s.model.cameras.at(1);
  for (size_t i = 0; i < s.names.size(); ++i) {
    fs::create_directories((dir / s.names[i]).parent_path());
    cv::imwrite((dir / s.names[i]).string(), Pattern(i, c.height, c.width));
  }
}

std::vector<TransformsFrame> ToTransforms(const Synthetic& s, bool drop_extension) {
  std::vector<TransformsFrame> frames;
  for (const ColmapImage& image : s.model.images) {
    TransformsFrame f;
    f.file_path = "images/" + (drop_extension ? fs::path(image.name).stem().string() : image.name);
    f.camera = s.model.cameras.at(image.camera_id);
    f.cam_from_world = image.cam_from_world;
    frames.push_back(f);
  }
  return frames;
}

Camera SmallPinhole() { return Camera::Pinhole(64, 48, 60, 60, 32, 24); }

void ExpectViewsMatch(const Dataset& ds, const Synthetic& s, double tol) {
  ASSERT_EQ(ds.NumViews(), static_cast<int>(s.names.size()));
  std::map<std::string, Rigid3d> poses;
  for (const ColmapImage& image : s.model.images) poses[image.name] = image.cam_from_world;
  for (int i = 0; i < ds.NumViews(); ++i) {
    const DatasetView& v = ds.views()[i];
    EXPECT_EQ(v.index, i);
    EXPECT_EQ(v.name, s.names[i]);
    const Eigen::Matrix<double, 3, 4> a = v.cam_from_world.ToMatrix(), b = poses.at(v.name).ToMatrix();
    EXPECT_LE((a - b).cwiseAbs().maxCoeff(), tol) << v.name;
  }
}

TEST(Dataset, AutoDetectColmapText) {
  TempDir tmp;
  const Synthetic s = MakeSynthetic(12, SmallPinhole());
  WriteImages(s, tmp.path() / "images");
  WriteColmapModelText(s.model, tmp.path() / "sparse");
  DatasetOptions options;
  options.dataset_dir = tmp.path();
  const Dataset ds = Dataset::Open(options);
  EXPECT_EQ(ds.pose_source(), "colmap-text");
  EXPECT_EQ(ds.root(), tmp.path());
  ExpectViewsMatch(ds, s, 1e-12);
  EXPECT_EQ(ds.views()[9].name, "frame_10.png");  // natural order, not "frame_1, frame_10, frame_11, frame_2"
  EXPECT_EQ(ds.ImagePath(0), tmp.path() / "images" / "frame_1.png");
  // No scene.json: V is estimated around the common look-at point.
  EXPECT_EQ(ds.bbox_source(), "estimated");
  EXPECT_LT((ds.bbox().Center() - kTarget).norm(), 1e-9);
  EXPECT_TRUE(ds.bbox().IsValid());
  // Half size: median distance (sqrt(5)) times tan(half the vertical field of view) = 24/60.
  EXPECT_NEAR(ds.bbox().Extent().x(), 2 * std::sqrt(5.0) * 24.0 / 60.0, 1e-9);
  EXPECT_FALSE(ds.GroundTruthDepthPath(0).has_value());
  EXPECT_FALSE(ds.GroundTruthMeshPath().has_value());
}

TEST(Dataset, AutoDetectBinaryInSparse0AndPrefersColmap) {
  TempDir tmp;
  const Synthetic s = MakeSynthetic(5, SmallPinhole());
  WriteImages(s, tmp.path() / "images");
  WriteColmapModelBinary(s.model, tmp.path() / "sparse" / "0");
  WriteTransformsJson({}, tmp.path() / "transforms.json");  // present, but COLMAP wins
  DatasetOptions options;
  options.dataset_dir = tmp.path();
  const Dataset ds = Dataset::Open(options);
  EXPECT_EQ(ds.pose_source(), "colmap-binary");
  ExpectViewsMatch(ds, s, 0.0);
}

TEST(Dataset, TransformsJsonWithoutExtensions) {
  TempDir tmp;
  const Synthetic s = MakeSynthetic(7, SmallPinhole());
  WriteImages(s, tmp.path() / "images");
  WriteTransformsJson(ToTransforms(s, /*drop_extension=*/true), tmp.path() / "transforms.json");
  DatasetOptions options;
  options.dataset_dir = tmp.path();
  const Dataset ds = Dataset::Open(options);
  EXPECT_EQ(ds.pose_source(), "transforms.json");
  ExpectViewsMatch(ds, s, 1e-12);
}

// NeRF-synthetic layout: no images/, file_paths like "./train/r_0" from the dataset folder.
TEST(Dataset, TransformsJsonWithoutImagesFolder) {
  TempDir tmp;
  Synthetic s = MakeSynthetic(3, SmallPinhole());
  for (size_t i = 0; i < s.names.size(); ++i) {
    s.names[i] = "train/r_" + std::to_string(i) + ".png";
    s.model.images[i].name = s.names[i];
  }
  WriteImages(s, tmp.path());
  std::vector<TransformsFrame> frames = ToTransforms(s, false);
  for (size_t i = 0; i < frames.size(); ++i) frames[i].file_path = "./train/r_" + std::to_string(i);
  WriteTransformsJson(frames, tmp.path() / "transforms.json");
  DatasetOptions options;
  options.dataset_dir = tmp.path();
  const Dataset ds = Dataset::Open(options);
  EXPECT_EQ(ds.images_dir(), tmp.path());
  ExpectViewsMatch(ds, s, 1e-12);
  auto source = ds.OpenFrames();
  Frame frame;
  ASSERT_TRUE(source->Next(&frame));
  EXPECT_EQ(frame.name, "train/r_0.png");
}

TEST(Dataset, ExplicitSources) {
  TempDir tmp;
  const Synthetic s = MakeSynthetic(6, SmallPinhole());
  WriteImages(s, tmp.path() / "pictures");
  WriteColmapModelText(s.model, tmp.path() / "recon" / "sparse" / "0");
  // transforms.json elsewhere, naming "images/...": matched by trailing components in --images.
  fs::create_directories(tmp.path() / "poses");
  WriteTransformsJson(ToTransforms(s, false), tmp.path() / "poses" / "transforms.json");

  DatasetOptions options;
  options.images_dir = tmp.path() / "pictures";
  options.colmap_dir = tmp.path() / "recon";
  Dataset ds = Dataset::Open(options);
  EXPECT_EQ(ds.pose_source(), "colmap-text");
  EXPECT_TRUE(ds.root().empty());
  ExpectViewsMatch(ds, s, 1e-12);

  options.colmap_dir.clear();
  options.transforms_path = tmp.path() / "poses" / "transforms.json";
  BoundingBox box;
  box.min = Eigen::Vector3d(-1, -2, -3);
  box.max = Eigen::Vector3d(1, 2, 3);
  options.bbox = box;
  ds = Dataset::Open(options);
  EXPECT_EQ(ds.pose_source(), "transforms.json");
  ExpectViewsMatch(ds, s, 1e-12);
  EXPECT_EQ(ds.bbox_source(), "--bbox");
  EXPECT_EQ(ds.bbox().max, box.max);
}

TEST(Dataset, SceneJsonBoundingBox) {
  TempDir tmp;
  const Synthetic s = MakeSynthetic(4, SmallPinhole());
  WriteImages(s, tmp.path() / "images");
  WriteColmapModelText(s.model, tmp.path() / "sparse");
  std::ofstream(tmp.path() / "scene.json") << R"({"foreground_bbox_min": [-0.5, -0.25, 0.125],
                                                   "foreground_bbox_max": [0.5, 0.75, 1]})";
  DatasetOptions options;
  options.dataset_dir = tmp.path();
  const Dataset ds = Dataset::Open(options);
  EXPECT_EQ(ds.bbox_source(), "scene.json");
  EXPECT_EQ(ds.bbox().min, Eigen::Vector3d(-0.5, -0.25, 0.125));
  EXPECT_EQ(ds.bbox().max, Eigen::Vector3d(0.5, 0.75, 1));
  std::ofstream(tmp.path() / "scene.json")
      << R"({"foreground_bbox_min": [0.5, 0, 0], "foreground_bbox_max": [0, 1, 1]})";
  ExpectInputError([&] { Dataset::Open(options); }, {"scene.json", "foreground_bbox"});
  std::ofstream(tmp.path() / "scene.json") << R"({"seed": 3})";  // no box: estimated
  EXPECT_EQ(Dataset::Open(options).bbox_source(), "estimated");
}

TEST(Dataset, OpenFramesUndistorts) {
  TempDir tmp;
  Camera cam;
  cam.model = CameraModelId::kOpenCV;
  cam.width = 64;
  cam.height = 48;
  cam.params = {60, 61, 32.5, 23.5, -0.2, 0.05, 0.001, -0.002};
  const Synthetic s = MakeSynthetic(3, cam);
  WriteImages(s, tmp.path() / "images");
  WriteColmapModelText(s.model, tmp.path() / "sparse");
  DatasetOptions options;
  options.dataset_dir = tmp.path();
  const Dataset ds = Dataset::Open(options);
  EXPECT_EQ(ds.views()[0].camera.model, CameraModelId::kOpenCV);
  const Camera undistorted = ds.UndistortedCamera(0);
  EXPECT_EQ(undistorted.model, CameraModelId::kPinhole);
  EXPECT_EQ(undistorted.params, (std::vector<double>{60, 61, 32.5, 23.5}));
  const PinholeView view = ds.View(1);
  EXPECT_LT((view.Center() - CameraCenter(ds.views()[1].cam_from_world)).norm(), 1e-12);

  const Undistorter undistorter(cam);
  auto frames = ds.OpenFrames();
  ASSERT_EQ(frames->NumFrames(), 3);
  Frame frame;
  int count = 0;
  while (frames->Next(&frame)) {
    EXPECT_EQ(frame.index, count);
    EXPECT_EQ(frame.name, s.names[count]);
    const cv::Mat raw = ReadImageFloat(ds.ImagePath(count));
    EXPECT_EQ(cv::norm(frame.image, undistorter.Apply(raw), cv::NORM_INF), 0.0);
    EXPECT_GT(cv::norm(frame.image, raw, cv::NORM_INF), 0.1);  // distortion was really removed
    ++count;
  }
  EXPECT_EQ(count, 3);
  EXPECT_EQ(frames->Read(2).name, s.names[2]);
}

TEST(Dataset, VideoFrames) {
  TempDir tmp;
  const Synthetic s = MakeSynthetic(10, SmallPinhole());
  const fs::path video = tmp.path() / "clip.avi";
  {
    cv::VideoWriter writer(video.string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0,
                           cv::Size(64, 48));
    if (!writer.isOpened()) GTEST_SKIP() << "OpenCV cannot write MJPG video here";
    for (int i = 0; i < 10; ++i) writer.write(cv::Mat(48, 64, CV_8UC3, cv::Scalar(20 * i, 100, 50)));
  }
  WriteColmapModelBinary(s.model, tmp.path() / "sparse");
  DatasetOptions options;
  options.video_path = video;
  options.colmap_dir = tmp.path() / "sparse";
  const Dataset ds = Dataset::Open(options);
  EXPECT_EQ(ds.NumViews(), 10);
  EXPECT_TRUE(ds.ImagePath(0).empty());
  auto frames = ds.OpenFrames();
  Frame frame;
  int count = 0;
  while (frames->Next(&frame)) {
    EXPECT_EQ(frame.name, s.names[count]);
    EXPECT_NEAR(frame.image.at<cv::Vec3f>(20, 20)[0], 20 * count / 255.0, 4 / 255.0);  // view k is frame k
    ++count;
  }
  EXPECT_EQ(count, 10);

  ColmapModel fewer = s.model;
  fewer.images.pop_back();
  WriteColmapModelBinary(fewer, tmp.path() / "sparse");
  ExpectInputError([&] { Dataset::Open(options); }, {"clip.avi", "10 frames", "9 poses"});
}

// ---------------------------------------------------------------------------
// Bad input

TEST(DatasetBadInput, ImageNamesThatLeaveTheImageFolderAreRefused) {
  for (const std::string bad : {"../secret.png", "sub/../../secret.png", "/etc/secret.png"}) {
    TempDir tmp;
    Synthetic s = MakeSynthetic(3, SmallPinhole());
    WriteImages(s, tmp.path() / "images");
    s.model.images[1].name = bad;
    WriteColmapModelText(s.model, tmp.path() / "sparse");
    DatasetOptions options;
    options.dataset_dir = tmp.path();
    try {
      Dataset::Open(options);
      ADD_FAILURE() << bad << " was accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("images.txt"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("leaves the image folder"), std::string::npos) << e.what();
    }
  }
}

TEST(DatasetBadInput, OptionsAndMissingFolders) {
  TempDir tmp;
  DatasetOptions options;
  EXPECT_THROW(options.Check(), OptionError);
  options.images_dir = tmp.path();
  options.video_path = tmp.path() / "v.mp4";
  options.colmap_dir = tmp.path();
  EXPECT_THROW(Dataset::Open(options), OptionError);

  options = DatasetOptions();
  options.dataset_dir = tmp.path() / "no_such_dataset";
  ExpectInputError([&] { Dataset::Open(options); }, {"no_such_dataset", "does not exist"});
  options.dataset_dir = tmp.path();
  ExpectInputError([&] { Dataset::Open(options); }, {tmp.path().string(), "no poses"});
  WriteColmapModelText(MakeSynthetic(2, SmallPinhole()).model, tmp.path() / "sparse");
  ExpectInputError([&] { Dataset::Open(options); }, {(tmp.path() / "images").string(), "does not exist"});

  options = DatasetOptions();
  options.images_dir = tmp.path() / "images";
  options.colmap_dir = tmp.path() / "missing_model";
  ExpectInputError([&] { Dataset::Open(options); }, {"missing_model", "does not exist"});
}

TEST(DatasetBadInput, ImageSizeDisagreesWithCamera) {
  TempDir tmp;
  const Synthetic s = MakeSynthetic(4, SmallPinhole());
  WriteImages(s, tmp.path() / "images");
  cv::imwrite((tmp.path() / "images" / s.names[2]).string(), Pattern(2, 48, 60));  // 60x48, camera says 64x48
  WriteColmapModelText(s.model, tmp.path() / "sparse");
  DatasetOptions options;
  options.dataset_dir = tmp.path();
  auto frames = Dataset::Open(options).OpenFrames();
  Frame frame;
  ASSERT_TRUE(frames->Next(&frame));
  ASSERT_TRUE(frames->Next(&frame));
  ExpectInputError([&] { frames->Next(&frame); }, {s.names[2], "60x48", "64x48"});
  ExpectInputError([&] { frames->Read(2); }, {s.names[2], "60x48", "64x48"});
}

// One frame's PNG header says 20000x20000 (decoding it took 6.8 GB): refused
// from the header, against its camera, naming the file.
TEST(DatasetBadInput, HugeFrameRefusedFromItsHeader) {
  TempDir tmp;
  const Synthetic s = MakeSynthetic(3, SmallPinhole());
  WriteImages(s, tmp.path() / "images");
  // Signature and IHDR (20000 x 20000, 8-bit RGB); the rest is never read.
  const std::string ihdr("\x00\x00\x00\x0dIHDR\x00\x00\x4e\x20\x00\x00\x4e\x20\x08\x02\x00\x00\x00", 21);
  std::ofstream(tmp.path() / "images" / s.names[1], std::ios::binary)
      << std::string("\x89PNG\r\n\x1a\n", 8) << ihdr << "\x00\x00\x00\x00 IDAT never decoded";
  WriteColmapModelText(s.model, tmp.path() / "sparse");
  DatasetOptions options;
  options.dataset_dir = tmp.path();
  auto frames = Dataset::Open(options).OpenFrames();
  Frame frame;
  ASSERT_TRUE(frames->Next(&frame));
  ExpectInputError([&] { frames->Next(&frame); }, {s.names[1], "header", "20000x20000", "64x48"});
}

TEST(DatasetBadInput, CorruptFrameNamesTheFile) {
  TempDir tmp;
  const Synthetic s = MakeSynthetic(3, SmallPinhole());
  WriteImages(s, tmp.path() / "images");
  std::ofstream(tmp.path() / "images" / s.names[1], std::ios::binary) << "\x89PNG\r\n\x1a\n garbage garbage";
  WriteColmapModelText(s.model, tmp.path() / "sparse");
  DatasetOptions options;
  options.dataset_dir = tmp.path();
  auto frames = Dataset::Open(options).OpenFrames();
  Frame frame;
  ASSERT_TRUE(frames->Next(&frame));
  ExpectInputError([&] { frames->Next(&frame); }, {s.names[1]});
}

TEST(DatasetBadInput, BadPoses) {
  TempDir tmp;
  Synthetic s = MakeSynthetic(3, SmallPinhole());
  WriteImages(s, tmp.path() / "images");
  s.model.images[1].cam_from_world.rotation.coeffs().setConstant(std::numeric_limits<double>::quiet_NaN());
  WriteColmapModelText(s.model, tmp.path() / "sparse");
  DatasetOptions options;
  options.dataset_dir = tmp.path();
  ExpectInputError([&] { Dataset::Open(options); }, {"images.txt", s.names[1], "quaternion"});

  s = MakeSynthetic(3, SmallPinhole());
  s.model.images[2].name = "not_there.png";
  WriteColmapModelBinary(s.model, tmp.path() / "sparse");
  fs::remove(tmp.path() / "sparse" / "images.txt");
  ExpectInputError([&] { Dataset::Open(options); }, {"not_there.png", "does not exist"});

  fs::remove_all(tmp.path() / "sparse");
  std::vector<TransformsFrame> frames = ToTransforms(MakeSynthetic(3, SmallPinhole()), false);
  frames[1].file_path = "images/ghost";
  WriteTransformsJson(frames, tmp.path() / "transforms.json");
  ExpectInputError([&] { Dataset::Open(options); }, {"transforms.json", "frames[1]", "images/ghost"});
}

// ---------------------------------------------------------------------------
// The figurines data set

fs::path FigurinesRoot() { return fs::path(LFRECON_SHARED_DIR) / "data" / "figurines"; }

TEST(DatasetFigurines, Opens) {
  const fs::path root = FigurinesRoot();
  if (!fs::exists(root / "images")) GTEST_SKIP() << "figurines data set not found at " << root;
  DatasetOptions options;
  options.dataset_dir = root;
  const Dataset ds = Dataset::Open(options);
  ASSERT_EQ(ds.NumViews(), 480);
  EXPECT_EQ(ds.pose_source(), "colmap-text");
  EXPECT_EQ(ds.views().front().name, "00000.jpg");
  EXPECT_EQ(ds.views().back().name, "00479.jpg");
  EXPECT_EQ(ds.bbox_source(), "scene.json");
  std::ifstream in(root / "scene.json");
  const nlohmann::json scene = nlohmann::json::parse(in);
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(ds.bbox().min[k], scene["foreground_bbox_min"][k].get<double>());
    EXPECT_EQ(ds.bbox().max[k], scene["foreground_bbox_max"][k].get<double>());
  }
  const BoundingBox estimated = EstimateBoundingBox(ds.views());
  EXPECT_TRUE(estimated.Contains(ds.bbox().Center()))
      << "estimated " << estimated.min.transpose() << " .. " << estimated.max.transpose();
  // Not absurdly large either: at most 4x the true box on every axis.
  EXPECT_TRUE((estimated.Extent().array() < 4 * ds.bbox().Extent().array()).all())
      << estimated.Extent().transpose();

  EXPECT_EQ(*ds.GroundTruthDepthPath(0), root / "depth" / "depth_0000.exr");
  EXPECT_EQ(*ds.GroundTruthDepthPath(472), root / "depth" / "depth_0472.exr");
  EXPECT_FALSE(ds.GroundTruthDepthPath(1).has_value());
  EXPECT_EQ(*ds.GroundTruthMeshPath(), root / "gt_mesh.ply");
  EXPECT_EQ(*ds.GroundTruthMeshPath(true), root / "gt_thin.ply");

  auto frames = ds.OpenFrames();
  Frame frame;
  ASSERT_TRUE(frames->Next(&frame));
  EXPECT_EQ(frame.name, "00000.jpg");
  ASSERT_EQ(frame.image.type(), CV_32FC3);
  ASSERT_EQ(frame.image.size(), cv::Size(640, 360));
  double lo, hi;
  cv::minMaxLoc(frame.image.reshape(1), &lo, &hi);
  EXPECT_GE(lo, 0.0);
  EXPECT_LE(hi, 1.0);
  EXPECT_GT(hi, 0.5);
}

// Ground-truth depth, poses and the pixel convention agree: unprojected depth
// lands on or above the table (z = 0) and fills the foreground box. (The
// backdrop walls at |x|, |y| = 3.45 m reach below the table's height, so only
// points nearer than 3 m horizontally count.)
TEST(DatasetFigurines, GroundTruthDepthMatchesPoses) {
  const fs::path root = FigurinesRoot();
  if (!fs::exists(root / "images")) GTEST_SKIP() << "figurines data set not found at " << root;
  DatasetOptions options;
  options.dataset_dir = root;
  const Dataset ds = Dataset::Open(options);
  for (int i : {0, 120, 344}) {
    const cv::Mat depth = ReadDepthMap(*ds.GroundTruthDepthPath(i));
    const PinholeView view = ds.View(i);
    int below = 0, on_table = 0, in_box = 0;
    for (int r = 0; r < depth.rows; ++r)
      for (int c = 0; c < depth.cols; ++c) {
        const Eigen::Vector3d X = view.Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), depth.at<float>(r, c));
        if (X.z() < -0.005 && X.head<2>().cwiseAbs().maxCoeff() < 3.0) ++below;
        if (std::abs(X.z()) < 0.002) ++on_table;
        if (ds.bbox().Contains(X) && X.z() > 0.005) ++in_box;
      }
    const double n = static_cast<double>(depth.total());
    std::printf("view %d: below table %.4f, on table %.3f, in V above table %.3f\n", i, below / n,
                on_table / n, in_box / n);
    EXPECT_LT(below / n, 0.001) << i;
    EXPECT_GT(on_table / n, 0.05) << i;
    EXPECT_GT(in_box / n, 0.05) << i;
  }
}

}  // namespace
}  // namespace lfrecon
