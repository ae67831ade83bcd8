// Inputs users have (issue 17): --max-image-size, Nerfstudio split folders
// (files without w/h, per-frame intrinsics, mask_path, OPENCV_FISHEYE), masks
// (a masks/ folder, an alpha channel) and V from them, EXIF orientation.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "common/test_util.h"
#include "io/colmap_model.h"
#include "io/dataset.h"
#include "io/frame_source.h"
#include "io/transforms_json.h"

namespace lfrecon {
namespace {

using testing::ExpectInputError;
using testing::TempDir;
namespace fs = std::filesystem;
using nlohmann::json;

const Eigen::Vector3d kTarget(0.1, -0.2, 0.3);
constexpr double kSphereRadius = 0.25;

std::vector<Rigid3d> Ring(int n) {
  std::vector<Rigid3d> poses;
  for (int i = 0; i < n; ++i) {
    const double a = 2 * M_PI * i / n;
    const Eigen::Vector3d eye = kTarget + Eigen::Vector3d(2 * std::cos(a), 2 * std::sin(a), 1.0);
    poses.push_back(LookAt(eye, kTarget, Eigen::Vector3d::UnitZ()));
  }
  return poses;
}

cv::Mat Pattern(int i, int rows, int cols) {
  cv::Mat m(rows, cols, CV_8UC3);
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c)
      m.at<cv::Vec3b>(r, c) = cv::Vec3b((c * 7 + r * 3) % 256, (r * 11) % 256, (i * 20 + (r / 5 + c / 3) % 2 * 90) % 256);
  return m;
}

// 255 where the pixel's ray (through its centre) passes within kSphereRadius of kTarget.
cv::Mat SphereMask(const Camera& camera, const Rigid3d& pose) {
  const PinholeView view(Camera::Pinhole(camera.width, camera.height, camera.fx(), camera.fy(), camera.cx(),
                                         camera.cy()),
                         pose);
  cv::Mat m(camera.height, camera.width, CV_8U);
  for (int r = 0; r < camera.height; ++r)
    for (int c = 0; c < camera.width; ++c) {
      const Eigen::Vector3d d = view.RayDirection(Eigen::Vector2d(c + 0.5, r + 0.5));
      const Eigen::Vector3d to = kTarget - view.Center();
      const double dist = (to - to.dot(d) * d).norm();
      m.at<std::uint8_t>(r, c) = dist < kSphereRadius ? 255 : 0;
    }
  return m;
}

// A COLMAP dataset: images/NNN.png, sparse/ (text).
void WriteColmapDataset(const fs::path& dir, const Camera& camera, int n) {
  ColmapModel model;
  model.cameras[1] = camera;
  const auto poses = Ring(n);
  fs::create_directories(dir / "images");
  for (int i = 0; i < n; ++i) {
    ColmapImage image;
    image.image_id = i + 1;
    image.camera_id = 1;
    image.name = "f" + std::to_string(100 + i) + ".png";
    image.cam_from_world = poses[i];
    model.images.push_back(image);
    cv::imwrite((dir / "images" / image.name).string(), Pattern(i, camera.height, camera.width));
  }
  WriteColmapModelText(model, dir / "sparse");
}

TEST(ScaledImageSize, LongerSideAtMostN) {
  EXPECT_EQ(ScaledImageSize(1280, 720, 0), std::make_pair(1280, 720));
  EXPECT_EQ(ScaledImageSize(1280, 720, 2000), std::make_pair(1280, 720));
  EXPECT_EQ(ScaledImageSize(1280, 720, 640), std::make_pair(640, 360));
  EXPECT_EQ(ScaledImageSize(720, 1280, 1000), std::make_pair(563, 1000));
  EXPECT_EQ(ScaledImageSize(3840, 2160, 1000), std::make_pair(1000, 563));
}

TEST(MaxImageSize, HalfSizeHalvesIntrinsicsAndEqualsInterArea) {
  TempDir tmp;
  const Camera full = Camera::Pinhole(64, 48, 61, 59, 31.5, 24.25);
  WriteColmapDataset(tmp.path(), full, 6);
  DatasetOptions options;
  options.dataset_dir = tmp.path();
  options.max_image_size = 32;
  const Dataset ds = Dataset::Open(options);
  ASSERT_EQ(ds.NumViews(), 6);
  const Camera c = ds.UndistortedCamera(0);
  EXPECT_EQ(c.width, 32);
  EXPECT_EQ(c.height, 24);
  // Exactly half: the upper-left pixel's centre (0.5, 0.5) becomes (0.25, 0.25), the extent [0, 64] -> [0, 32].
  EXPECT_EQ(c.fx(), 30.5);
  EXPECT_EQ(c.fy(), 29.5);
  EXPECT_EQ(c.cx(), 15.75);
  EXPECT_EQ(c.cy(), 12.125);
  EXPECT_EQ(ds.views()[0].source_width, 64);
  EXPECT_EQ(ds.views()[0].source_height, 48);
  auto frames = ds.OpenFrames();
  Frame f;
  for (int i = 0; i < 2; ++i) {
    ASSERT_TRUE(frames->Next(&f));
    ASSERT_EQ(f.image.size(), cv::Size(32, 24));
    cv::Mat expect;
    cv::resize(ToFloatBgr(Pattern(i, 48, 64)), expect, cv::Size(32, 24), 0, 0, cv::INTER_AREA);
    EXPECT_EQ(cv::norm(f.image, expect, cv::NORM_INF), 0.0) << i;
  }
  // The same point projects to half the pixel coordinates.
  const PinholeView small = ds.View(3);
  options.max_image_size = 0;
  const PinholeView big = Dataset::Open(options).View(3);
  Eigen::Vector2d ps, pb;
  ASSERT_GT(small.Project(kTarget + Eigen::Vector3d(0.05, 0.02, -0.03), &ps), 0);
  ASSERT_GT(big.Project(kTarget + Eigen::Vector3d(0.05, 0.02, -0.03), &pb), 0);
  EXPECT_LT((ps - 0.5 * pb).norm(), 1e-12);
  options.max_image_size = -1;
  EXPECT_THROW(Dataset::Open(options), OptionError);
}

TEST(MaxImageSize, DistortedCameraScaledBeforeUndistortion) {
  TempDir tmp;
  Camera full;
  full.model = CameraModelId::kSimpleRadial;
  full.width = 64;
  full.height = 48;
  full.params = {60, 32, 24, -0.05};
  WriteColmapDataset(tmp.path(), full, 3);
  DatasetOptions options;
  options.dataset_dir = tmp.path();
  options.max_image_size = 40;  // 40x30: 0.625 both ways
  const Dataset ds = Dataset::Open(options);
  const Camera& c = ds.views()[0].camera;
  EXPECT_EQ(c.model, CameraModelId::kSimpleRadial);
  EXPECT_EQ(c.width, 40);
  EXPECT_EQ(c.height, 30);
  EXPECT_DOUBLE_EQ(c.fx(), 37.5);
  EXPECT_DOUBLE_EQ(c.cx(), 20);
  EXPECT_EQ(c.params[3], -0.05);  // distortion acts on normalised coordinates: unchanged
  auto frames = ds.OpenFrames();
  Frame f;
  ASSERT_TRUE(frames->Next(&f));
  EXPECT_EQ(f.image.size(), cv::Size(40, 30));
}

TEST(CameraScaled, UnequalFactorsGiveTwoFocalModel) {
  Camera c;
  c.model = CameraModelId::kSimpleRadialFisheye;
  c.width = 100;
  c.height = 75;
  c.params = {80, 50, 37.5, 0.03};
  const Camera s = c.Scaled(50, 38);  // 0.5 x, 38/75 y
  EXPECT_EQ(s.model, CameraModelId::kOpenCVFisheye);
  EXPECT_EQ(s.Validate(), "");
  EXPECT_DOUBLE_EQ(s.fx(), 40);
  EXPECT_DOUBLE_EQ(s.fy(), 80 * 38.0 / 75.0);
  EXPECT_DOUBLE_EQ(s.cy(), 37.5 * 38.0 / 75.0);
  EXPECT_EQ(s.params[4], 0.03);
}

// A Nerfstudio-style folder: images/, masks/, transforms_train.json (even
// frames, shared intrinsics) and transforms_val.json (odd frames, per-frame
// focal lengths), neither with w/h; each frame names its mask_path.
struct NerfstudioFolder {
  std::vector<Rigid3d> poses;
  std::vector<double> fx;
};

NerfstudioFolder WriteNerfstudio(const fs::path& dir, int n, const Camera& cam, const std::string& model = "") {
  NerfstudioFolder out;
  out.poses = Ring(n);
  fs::create_directories(dir / "images");
  fs::create_directories(dir / "masks");
  json train = {{"fl_x", cam.fx()}, {"fl_y", cam.fy()}, {"cx", cam.cx()}, {"cy", cam.cy()}};
  if (!model.empty()) {
    train["camera_model"] = model;
    for (int k = 0; k < 4; ++k) train["k" + std::to_string(k + 1)] = cam.params[4 + k];
  }
  json val = {{"cx", cam.cx()}, {"cy", cam.cy()}};
  if (!model.empty()) val["camera_model"] = model;
  if (!model.empty())
    for (int k = 0; k < 4; ++k) val["k" + std::to_string(k + 1)] = cam.params[4 + k];
  train["frames"] = json::array();
  val["frames"] = json::array();
  for (int i = 0; i < n; ++i) {
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%05d.png", i + 1);
    cv::imwrite((dir / "images" / name).string(), Pattern(i, cam.height, cam.width));
    Camera frame_cam = cam;  // odd frames: their own focal length
    if (i % 2 == 1) frame_cam.params[0] = frame_cam.params[1] = cam.fx() + i;
    cv::imwrite((dir / "masks" / name).string(), SphereMask(frame_cam, out.poses[i]));
    // camera-to-world, OpenGL axes, as Nerfstudio writes them
    Eigen::Matrix4d c2w = Eigen::Matrix4d::Identity();
    c2w.topLeftCorner<3, 4>() = out.poses[i].Inverse().ToMatrix();
    c2w.col(1) *= -1;
    c2w.col(2) *= -1;
    json m = json::array();
    for (int r = 0; r < 4; ++r) m.push_back({c2w(r, 0), c2w(r, 1), c2w(r, 2), c2w(r, 3)});
    json frame = {{"file_path", std::string("images/") + name},
                  {"mask_path", std::string("masks/") + name},
                  {"transform_matrix", m}};
    if (i % 2 == 0) {
      train["frames"].push_back(frame);
      out.fx.push_back(cam.fx());
    } else {
      const double f = cam.fx() + i;  // per-frame intrinsics
      frame["fl_x"] = f;
      frame["fl_y"] = f;
      val["frames"].push_back(frame);
      out.fx.push_back(f);
    }
  }
  std::ofstream(dir / "transforms_train.json") << train.dump(1);
  std::ofstream(dir / "transforms_val.json") << val.dump(1);
  return out;
}

TEST(Nerfstudio, SplitFilesWithoutSizePerFrameIntrinsicsAndMaskPath) {
  TempDir tmp;
  const Camera cam = Camera::Pinhole(80, 60, 70, 70, 40, 30);
  const NerfstudioFolder ns = WriteNerfstudio(tmp.path(), 12, cam);
  DatasetOptions options;
  options.dataset_dir = tmp.path();
  const Dataset ds = Dataset::Open(options);
  ASSERT_EQ(ds.NumViews(), 12);  // both splits
  EXPECT_EQ(ds.pose_source(), "transforms splits");
  EXPECT_EQ(ds.mask_source(), "mask_path");
  for (int i = 0; i < 12; ++i) {
    const DatasetView& v = ds.views()[i];
    char name[32];
    std::snprintf(name, sizeof(name), "frame_%05d.png", i + 1);
    EXPECT_EQ(v.name, name);
    EXPECT_EQ(v.camera.width, 80);  // from the image header
    EXPECT_EQ(v.camera.height, 60);
    EXPECT_DOUBLE_EQ(v.camera.fx(), ns.fx[i]);
    EXPECT_LT((v.cam_from_world.ToMatrix() - ns.poses[i].ToMatrix()).cwiseAbs().maxCoeff(), 1e-9);
    EXPECT_EQ(v.mask_path, tmp.path() / "masks" / name);
  }
  const cv::Mat mask = ds.ReadMask(3);
  ASSERT_EQ(mask.type(), CV_8U);
  EXPECT_EQ(cv::countNonZero(mask != SphereMask(ds.UndistortedCamera(3), ns.poses[3])), 0);
  // V from the masks' visual hull: around the sphere, not the cameras' whole view.
  EXPECT_EQ(ds.bbox_source(), "masks (mask_path)");
  EXPECT_LT((ds.bbox().Center().head<2>() - kTarget.head<2>()).norm(), 0.03);
  for (int k = 0; k < 3; ++k) {
    EXPECT_LE(ds.bbox().min[k], kTarget[k] - kSphereRadius + 0.01) << k;
    EXPECT_GE(ds.bbox().max[k], kTarget[k] + kSphereRadius - 0.01) << k;
  }
  EXPECT_LT(ds.bbox().Extent().x(), 2 * kSphereRadius * 1.3);
  EXPECT_LT(ds.bbox().Extent().y(), 2 * kSphereRadius * 1.3);
  // A ring of cameras at one height sees the hull longer than the sphere along z.
  EXPECT_LT(ds.bbox().Extent().z(), 2 * kSphereRadius * 2.0);

  // Train only: the explicit file.
  options = DatasetOptions();
  options.images_dir = tmp.path() / "images";
  options.transforms_path = tmp.path() / "transforms_train.json";
  const Dataset train = Dataset::Open(options);
  EXPECT_EQ(train.NumViews(), 6);
  EXPECT_EQ(train.pose_source(), "transforms_train.json");
}

TEST(Nerfstudio, MaskPathMustStayInTheFolder) {
  TempDir tmp;
  WriteNerfstudio(tmp.path(), 4, Camera::Pinhole(40, 30, 35, 35, 20, 15));
  json j;
  std::ifstream(tmp.path() / "transforms_train.json") >> j;
  j["frames"][0]["mask_path"] = "../secret.png";
  std::ofstream(tmp.path() / "transforms_train.json") << j.dump();
  DatasetOptions options;
  options.dataset_dir = tmp.path();
  ExpectInputError([&] { Dataset::Open(options); }, {"transforms_train.json", "mask_path", "leaves"});
}

TEST(Nerfstudio, OpenCvFisheyeIsUndistorted) {
  TempDir tmp;
  Camera cam;
  cam.model = CameraModelId::kOpenCVFisheye;
  cam.width = 80;
  cam.height = 60;
  cam.params = {50, 50, 40, 30, 0.05, -0.01, 0.002, -0.0005};
  WriteNerfstudio(tmp.path(), 4, cam, "OPENCV_FISHEYE");
  DatasetOptions options;
  options.dataset_dir = tmp.path();
  options.max_image_size = 40;
  const Dataset ds = Dataset::Open(options);
  const Camera& c = ds.views()[0].camera;
  EXPECT_EQ(c.model, CameraModelId::kOpenCVFisheye);
  EXPECT_EQ(c.width, 40);
  EXPECT_DOUBLE_EQ(c.fx(), 25);
  EXPECT_EQ(c.params[4], 0.05);
  EXPECT_EQ(ds.UndistortedCamera(0).model, CameraModelId::kPinhole);
  auto frames = ds.OpenFrames();
  Frame f;
  ASSERT_TRUE(frames->Next(&f));
  EXPECT_EQ(f.image.size(), cv::Size(40, 30));
  // Written back by WriteTransformsJson as OPENCV_FISHEYE with k1..k4.
  WriteTransformsJson({TransformsFrame{"images/frame_00001.png", cam, Rigid3d(), ""}}, tmp.path() / "t.json");
  const auto back = ReadTransformsJson(tmp.path() / "t.json");
  ASSERT_EQ(back.size(), 1u);
  EXPECT_EQ(back[0].camera.model, CameraModelId::kOpenCVFisheye);
  EXPECT_EQ(back[0].camera.params, cam.params);
}

TEST(Masks, FolderAndAlphaChannelGiveTheSameV) {
  TempDir tmp;
  const Camera cam = Camera::Pinhole(80, 60, 70, 70, 40, 30);
  const int n = 10;
  WriteColmapDataset(tmp.path() / "folder", cam, n);
  DatasetOptions options;
  options.dataset_dir = tmp.path() / "folder";
  const Dataset plain = Dataset::Open(options);
  EXPECT_EQ(plain.bbox_source(), "estimated");
  EXPECT_FALSE(plain.HasMasks());
  // masks/NAME.png (COLMAP's naming) for every image.
  fs::create_directories(tmp.path() / "folder" / "masks");
  fs::copy(tmp.path() / "folder", tmp.path() / "alpha", fs::copy_options::recursive);
  fs::remove_all(tmp.path() / "alpha" / "masks");
  for (int i = 0; i < n; ++i) {
    const DatasetView& v = plain.views()[i];
    const cv::Mat mask = SphereMask(cam, v.cam_from_world);
    cv::imwrite((tmp.path() / "folder" / "masks" / (v.name + ".png")).string(), mask);
    cv::Mat bgra;
    cv::cvtColor(Pattern(i, cam.height, cam.width), bgra, cv::COLOR_BGR2BGRA);
    cv::insertChannel(mask, bgra, 3);
    cv::imwrite((tmp.path() / "alpha" / "images" / v.name).string(), bgra);
  }
  const Dataset folder = Dataset::Open(options);
  EXPECT_EQ(folder.mask_source(), "masks/");
  EXPECT_EQ(folder.bbox_source(), "masks (masks/)");
  options.dataset_dir = tmp.path() / "alpha";
  const Dataset alpha = Dataset::Open(options);
  EXPECT_EQ(alpha.mask_source(), "alpha");
  EXPECT_LT((alpha.bbox().min - folder.bbox().min).norm(), 1e-9);
  EXPECT_LT((alpha.bbox().max - folder.bbox().max).norm(), 1e-9);
  // The camera estimate is several times larger than the hull's bounds.
  EXPECT_GT(plain.bbox().Extent().x(), 2.5 * folder.bbox().Extent().x());
  for (int k = 0; k < 3; ++k) {
    EXPECT_LE(folder.bbox().min[k], kTarget[k] - kSphereRadius + 0.01);
    EXPECT_GE(folder.bbox().max[k], kTarget[k] + kSphereRadius - 0.01);
  }
  // Frames of RGBA images are BGR; scene.json still wins over masks.
  auto frames = alpha.OpenFrames();
  Frame f;
  ASSERT_TRUE(frames->Next(&f));
  EXPECT_EQ(f.image.type(), CV_32FC3);
  std::ofstream(tmp.path() / "alpha" / "scene.json")
      << R"({"foreground_bbox_min": [0, -0.3, 0.2], "foreground_bbox_max": [0.2, -0.1, 0.4]})";
  EXPECT_EQ(Dataset::Open(options).bbox_source(), "scene.json");
  // A mask of the wrong size names its file.
  options.dataset_dir = tmp.path() / "folder";
  const Dataset again = Dataset::Open(options);
  cv::imwrite((tmp.path() / "folder" / "masks" / (again.views()[2].name + ".png")).string(), cv::Mat(10, 10, CV_8U));
  ExpectInputError([&] { again.ReadMask(2); }, {again.views()[2].name + ".png", "10x10"});
}

// Dataset::ReadMask checks a mask's header against its image before decoding
// it: a mask whose header says 20000x20000 (1.2 GB as 8-bit RGB) or a size
// that does not match is refused naming the file, from the header alone (the
// files hold no pixels: a decoder would fail with "cannot be read").
TEST(Masks, HeaderCheckedBeforeDecoding) {
  TempDir tmp;
  const Camera cam = Camera::Pinhole(80, 60, 70, 70, 40, 30);
  const int n = 4;
  WriteColmapDataset(tmp.path(), cam, n);
  fs::create_directories(tmp.path() / "masks");
  // V from scene.json: Open reads no mask.
  std::ofstream(tmp.path() / "scene.json")
      << R"({"foreground_bbox_min": [-0.2, -0.5, 0.0], "foreground_bbox_max": [0.4, 0.1, 0.6]})";
  DatasetOptions options;
  options.dataset_dir = tmp.path();
  const Dataset probe = Dataset::Open(options);
  for (int i = 0; i < n; ++i)
    cv::imwrite((tmp.path() / "masks" / (probe.views()[i].name + ".png")).string(),
                SphereMask(cam, probe.views()[i].cam_from_world));
  const Dataset ds = Dataset::Open(options);
  ASSERT_EQ(ds.mask_source(), "masks/");
  ASSERT_EQ(ds.bbox_source(), "scene.json");
  EXPECT_EQ(ds.ReadMask(0).size(), cv::Size(80, 60));
  // A PNG signature and IHDR of 20000 x 20000, 8-bit RGB; no image data.
  const std::string huge_name = ds.views()[1].name + ".png";
  std::ofstream(tmp.path() / "masks" / huge_name, std::ios::binary)
      << std::string("\x89PNG\r\n\x1a\n", 8)
      << std::string("\x00\x00\x00\x0dIHDR\x00\x00\x4e\x20\x00\x00\x4e\x20\x08\x02\x00\x00\x00", 21)
      << "\x00\x00\x00\x00 IDAT never decoded";
  ExpectInputError([&] { ds.ReadMask(1); }, {huge_name, "mask header is 20000x20000", "80x60"});
  // A BMP header (whatever the file's name says) of 81 x 60: one pixel too wide.
  std::string bmp = "BM" + std::string(12, '\0');
  for (const std::int32_t v : {40, 81, 60}) bmp += std::string(reinterpret_cast<const char*>(&v), 4);
  bmp += std::string(28, '\0');
  const std::string wide_name = ds.views()[2].name + ".png";
  std::ofstream(tmp.path() / "masks" / wide_name, std::ios::binary) << bmp;
  ExpectInputError([&] { ds.ReadMask(2); }, {wide_name, "mask header is 81x60", "80x60"});
  // The same header with the right size is not refused by the check: it fails to decode.
  bmp.replace(18, 4, std::string("\x50\x00\x00\x00", 4));
  std::ofstream(tmp.path() / "masks" / wide_name, std::ios::binary) << bmp;
  ExpectInputError([&] { ds.ReadMask(2); }, {wide_name, "mask cannot be read"});
  // The other masks are still read.
  EXPECT_EQ(ds.ReadMask(3).size(), cv::Size(80, 60));
}

// A JPEG whose EXIF says "rotate 90° clockwise to display" (orientation 6).
std::string JpegWithExifOrientation(const cv::Mat& image, int orientation) {
  std::vector<uchar> jpg;
  cv::imencode(".jpg", image, jpg);
  // APP1: "Exif\0\0", little-endian TIFF header, IFD0 with one SHORT entry 0x0112.
  std::string tiff = std::string("II*\0", 4) + std::string("\x08\0\0\0", 4);
  tiff += std::string("\x01\0", 2);                                   // one entry
  tiff += std::string("\x12\x01\x03\0\x01\0\0\0", 8);                 // tag 0x0112, SHORT, count 1
  tiff += std::string(1, static_cast<char>(orientation)) + std::string("\0\0\0", 3);
  tiff += std::string("\0\0\0\0", 4);                                 // no next IFD
  const std::string payload = std::string("Exif\0\0", 6) + tiff;
  const int length = static_cast<int>(payload.size()) + 2;
  std::string app1 = "\xFF\xE1";
  app1 += static_cast<char>(length >> 8);
  app1 += static_cast<char>(length & 0xFF);
  app1 += payload;
  std::string bytes(jpg.begin(), jpg.end());
  return bytes.substr(0, 2) + app1 + bytes.substr(2);
}

TEST(ExifOrientation, IgnoredAsColmapDoes) {
  TempDir tmp;
  const cv::Mat image = Pattern(0, 30, 40);  // 40 wide, 30 high
  const fs::path file = tmp.path() / "rotated.jpg";
  std::ofstream(file, std::ios::binary) << JpegWithExifOrientation(image, 6);
  // OpenCV's default read applies the orientation: 30 wide, 40 high.
  const cv::Mat displayed = cv::imread(file.string());
  ASSERT_EQ(displayed.size(), cv::Size(30, 40)) << "the fixture's EXIF orientation is not recognised";
  // Ours keeps the pixels as stored, like COLMAP, whose cameras describe them.
  const cv::Mat stored = ReadImageFloat(file, cv::Size(40, 30));
  EXPECT_EQ(stored.size(), cv::Size(40, 30));
}

}  // namespace
}  // namespace lfrecon
