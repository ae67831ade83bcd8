#include "io/colmap_model.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <random>

#include "io/transforms_json.h"
#include "util/error.h"
#include "common/test_util.h"

namespace lfrecon {
namespace {

using testing::TempDir;
using testing::ExpectInputError;
namespace fs = std::filesystem;

// A per-test folder under the system temp folder, removed afterwards.
// Runs f and expects an InputError whose message contains every needle.
ColmapModel MakeModel() {
  ColmapModel model;
  const std::vector<std::pair<CameraModelId, std::vector<double>>> specs = {
      {CameraModelId::kSimplePinhole, {500.25, 320, 240}},
      {CameraModelId::kPinhole, {500.125, 510.5, 321.75, 239.25}},
      {CameraModelId::kSimpleRadial, {501, 320, 240, -0.0812345678901234}},
      {CameraModelId::kRadial, {502, 320, 240, -0.08, 0.0213}},
      {CameraModelId::kOpenCV, {500, 505, 320, 240, -0.1, 0.03, 0.001, -0.002}},
      {CameraModelId::kFullOpenCV,
       {500, 505, 320, 240, -0.1, 0.03, 0.001, -0.002, 0.001, 0.01, 0.002, 0.0005}},
      {CameraModelId::kOpenCVFisheye, {300, 305, 320, 240, 0.05, -0.01, 0.002, -0.0005}},
      {CameraModelId::kFov, {300, 305, 320, 240, 0.6}},
      {CameraModelId::kSimpleRadialFisheye, {300, 320, 240, 0.04}},
      {CameraModelId::kRadialFisheye, {300, 322, 238, 0.04, -0.006}},
      {CameraModelId::kThinPrismFisheye, {300, 305, 320, 240, 0.03, -0.01, 0.001, -0.002, 0.001, 0.0005, 0.001, -0.001}}};
  std::uint32_t id = 3;  // non-contiguous ids on purpose
  for (const auto& [m, params] : specs) {
    Camera c;
    c.model = m;
    c.width = 640 + static_cast<int>(id);
    c.height = 480;
    c.params = params;
    model.cameras[id] = c;
    id += 2;
  }
  std::mt19937 rng(42);
  std::normal_distribution<double> n(0.0, 1.0);
  std::vector<std::uint32_t> cam_ids;
  for (const auto& [cid, c] : model.cameras) cam_ids.push_back(cid);
  for (int i = 0; i < 12; ++i) {
    ColmapImage image;
    image.image_id = 100 - i;
    image.camera_id = cam_ids[i % cam_ids.size()];
    image.name = (i % 3 == 0 ? "sub dir/" : "") + std::string("img_") + std::to_string(1000 + 7 * i) + ".jpg";
    Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
    q.normalize();
    image.cam_from_world = Rigid3d(q, Eigen::Vector3d(n(rng), n(rng), n(rng)) * 3.0);
    model.images.push_back(image);
  }
  std::sort(model.images.begin(), model.images.end(),
            [](const ColmapImage& a, const ColmapImage& b) { return a.name < b.name; });
  return model;
}

void ExpectModelsEqual(const ColmapModel& a, const ColmapModel& b, double tol) {
  ASSERT_EQ(a.cameras.size(), b.cameras.size());
  for (const auto& [id, ca] : a.cameras) {
    ASSERT_TRUE(b.cameras.count(id)) << id;
    const Camera& cb = b.cameras.at(id);
    EXPECT_EQ(ca.model, cb.model);
    EXPECT_EQ(ca.width, cb.width);
    EXPECT_EQ(ca.height, cb.height);
    ASSERT_EQ(ca.params.size(), cb.params.size());
    for (size_t k = 0; k < ca.params.size(); ++k) EXPECT_NEAR(ca.params[k], cb.params[k], tol);
  }
  ASSERT_EQ(a.images.size(), b.images.size());
  for (size_t i = 0; i < a.images.size(); ++i) {
    const ColmapImage& ia = a.images[i];
    const ColmapImage& ib = b.images[i];
    EXPECT_EQ(ia.name, ib.name);
    EXPECT_EQ(ia.image_id, ib.image_id);
    EXPECT_EQ(ia.camera_id, ib.camera_id);
    EXPECT_LE(
        (ia.cam_from_world.rotation.coeffs() - ib.cam_from_world.rotation.coeffs()).cwiseAbs().maxCoeff(),
        tol);
    EXPECT_LE((ia.cam_from_world.translation - ib.cam_from_world.translation).cwiseAbs().maxCoeff(), tol);
  }
}

TEST(ColmapModel, TextRoundTrip) {
  TempDir tmp;
  const ColmapModel model = MakeModel();
  WriteColmapModelText(model, tmp.path());
  EXPECT_FALSE(IsColmapModelBinary(tmp.path()));
  const ColmapModel read = ReadColmapModel(tmp.path());
  ExpectModelsEqual(model, read, 1e-12);
  EXPECT_EQ(read.num_points3D, 0u);
}

TEST(ColmapModel, BinaryRoundTripIsExact) {
  TempDir tmp;
  const ColmapModel model = MakeModel();
  WriteColmapModelBinary(model, tmp.path());
  EXPECT_TRUE(IsColmapModelBinary(tmp.path()));
  ExpectModelsEqual(model, ReadColmapModel(tmp.path()), 0.0);
}

// A binary model written by COLMAP itself (`colmap model_converter`, the text
// model in, BIN out) reads back as the model it came from. Skips without colmap.
TEST(ColmapModel, BinaryWrittenByColmapModelConverter) {
  if (std::system("command -v colmap > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "colmap is not installed (deploy/install_deps.sh installs Debian's colmap)";
  TempDir tmp;
  ColmapModel model = MakeModel();
  // COLMAP's text reader splits lines at whitespace: no spaces in names here.
  for (ColmapImage& image : model.images) std::replace(image.name.begin(), image.name.end(), ' ', '_');
  const fs::path text = tmp.path() / "text", binary = tmp.path() / "binary";
  WriteColmapModelText(model, text);
  fs::create_directories(binary);
  const std::string cmd = "colmap model_converter --input_path '" + text.string() + "' --output_path '" +
                          binary.string() + "' --output_type BIN > '" + (tmp.path() / "log.txt").string() + "' 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  ASSERT_TRUE(IsColmapModelBinary(binary));
  ExpectModelsEqual(model, ReadColmapModel(binary), 1e-12);
}

TEST(ColmapModel, FindsModelInSparseOrSparse0) {
  TempDir tmp;
  EXPECT_TRUE(FindColmapModel(tmp.path()).empty());
  WriteColmapModelBinary(MakeModel(), tmp.path() / "sparse" / "0");
  EXPECT_EQ(FindColmapModel(tmp.path()), tmp.path() / "sparse" / "0");
  WriteColmapModelText(MakeModel(), tmp.path() / "sparse");
  EXPECT_EQ(FindColmapModel(tmp.path()), tmp.path() / "sparse");
  EXPECT_EQ(FindColmapModel(tmp.path() / "sparse" / "0"), tmp.path() / "sparse" / "0");
}

TEST(ColmapModel, TextWithPointsAndWithoutPoints2DLines) {
  TempDir tmp;
  std::ofstream(tmp.path() / "cameras.txt") << "# c\n1 PINHOLE 64 48 50 50 32 24\n";
  // Image 1 has a POINTS2D line, image 2 has none at all (some writers skip it).
  std::ofstream(tmp.path() / "images.txt") << "# i\n"
                                              "1 1 0 0 0 0.5 0 1 1 b.png\n"
                                              "10.5 20.5 -1 30 40 7\n"
                                              "2 0 1 0 0 0 0 2 1 a.png\n";
  std::ofstream(tmp.path() / "points3D.txt") << "# p\n7 0 0 0 255 0 0 0.1 1 1\n8 1 1 1 0 255 0 0.2 1 1\n";
  const ColmapModel m = ReadColmapModelText(tmp.path());
  ASSERT_EQ(m.images.size(), 2u);
  EXPECT_EQ(m.images[0].name, "a.png");  // sorted by name
  EXPECT_EQ(m.images[0].image_id, 2u);
  EXPECT_NEAR(m.images[0].cam_from_world.translation.z(), 2.0, 0);
  EXPECT_EQ(m.images[1].name, "b.png");
  EXPECT_NEAR(m.images[1].cam_from_world.translation.x(), 0.5, 0);
  EXPECT_EQ(m.num_points3D, 2u);
}

TEST(ColmapModel, NonUnitQuaternionIsNormalised) {
  TempDir tmp;
  std::ofstream(tmp.path() / "cameras.txt") << "1 PINHOLE 64 48 50 50 32 24\n";
  std::ofstream(tmp.path() / "images.txt") << "1 2 0 0 0 0 0 1 1 a.png\n\n";
  const ColmapModel m = ReadColmapModelText(tmp.path());
  EXPECT_NEAR(m.images[0].cam_from_world.rotation.w(), 1.0, 1e-15);
}

TEST(ColmapModel, FigurinesMatchesTransformsJson) {
  const fs::path root = fs::path(LFRECON_SHARED_DIR) / "data" / "figurines";
  if (!fs::exists(root / "sparse")) GTEST_SKIP() << "figurines data set not found at " << root;
  ASSERT_EQ(FindColmapModel(root), root / "sparse");
  const ColmapModel model = ReadColmapModel(FindColmapModel(root));
  ASSERT_EQ(model.images.size(), 480u);
  ASSERT_EQ(model.cameras.size(), 1u);
  const Camera& cam = model.cameras.begin()->second;
  EXPECT_EQ(cam.model, CameraModelId::kPinhole);
  EXPECT_EQ(cam.width, 640);
  EXPECT_EQ(cam.height, 360);
  EXPECT_EQ(model.images.front().name, "00000.jpg");
  EXPECT_EQ(model.images.back().name, "00479.jpg");

  const std::vector<TransformsFrame> frames = ReadTransformsJson(root / "transforms.json");
  ASSERT_EQ(frames.size(), 480u);
  std::map<std::string, Rigid3d> by_name;
  for (const auto& f : frames) by_name[fs::path(f.file_path).filename().string()] = f.cam_from_world;
  double max_center = 0, max_dir = 0;
  for (const ColmapImage& image : model.images) {
    ASSERT_TRUE(by_name.count(image.name)) << image.name;
    const Rigid3d& t = by_name[image.name];
    max_center = std::max(max_center, (CameraCenter(image.cam_from_world) - CameraCenter(t)).norm());
    max_dir = std::max(max_dir, (ViewingDirection(image.cam_from_world) - ViewingDirection(t)).norm());
  }
  EXPECT_LT(max_center, 1e-6);
  EXPECT_LT(max_dir, 1e-6);
}

// ---------------------------------------------------------------------------
// Bad input

std::string ReadBytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}
void WriteBytes(const fs::path& p, const std::string& s) { std::ofstream(p, std::ios::binary) << s; }

TEST(ColmapModelBadInput, TruncatedBinaryFilesNameTheFile) {
  TempDir tmp;
  const ColmapModel model = MakeModel();
  for (const char* name : {"cameras.bin", "images.bin"}) {
    const fs::path dir = tmp.path() / name;
    WriteColmapModelBinary(model, dir);
    const std::string full = ReadBytes(dir / name);
    ASSERT_GT(full.size(), 100u);
    for (size_t cut : {size_t(0), size_t(3), size_t(8), size_t(12), size_t(21), size_t(37), full.size() / 2,
                       full.size() - 9, full.size() - 1}) {
      WriteBytes(dir / name, full.substr(0, cut));
      SCOPED_TRACE(std::string(name) + " cut at " + std::to_string(cut));
      ExpectInputError([&] { ReadColmapModelBinary(dir); }, {name, "truncated"});
    }
  }
}

TEST(ColmapModelBadInput, HugeCountsDoNotAllocate) {
  TempDir tmp;
  WriteColmapModelBinary(MakeModel(), tmp.path());
  for (const char* name : {"cameras.bin", "images.bin", "points3D.bin"}) {
    const std::string full = ReadBytes(tmp.path() / name);
    std::string bad = full;
    const std::uint64_t huge = std::uint64_t(1) << 60;
    std::memcpy(bad.data(), &huge, 8);
    WriteBytes(tmp.path() / name, bad);
    SCOPED_TRACE(name);
    ExpectInputError([&] { ReadColmapModelBinary(tmp.path()); }, {name});
    WriteBytes(tmp.path() / name, full);
  }
  // A truncated points3D.bin is reported too, not silently counted.
  std::string points(8, '\0');
  const std::uint64_t one = 1;
  std::memcpy(points.data(), &one, 8);
  WriteBytes(tmp.path() / "points3D.bin", points + std::string(20, '\0'));
  ExpectInputError([&] { ReadColmapModelBinary(tmp.path()); }, {"points3D.bin", "truncated"});
}

TEST(ColmapModelBadInput, NanQuaternionTextNamesFileAndImage) {
  TempDir tmp;
  std::ofstream(tmp.path() / "cameras.txt") << "1 PINHOLE 64 48 50 50 32 24\n";
  std::ofstream(tmp.path() / "images.txt") << "1 1 0 0 0 0 0 1 1 good.png\n\n"
                                              "2 nan 0 0 0 0 0 1 1 frame_0002.png\n\n";
  ExpectInputError([&] { ReadColmapModel(tmp.path()); },
                   {"images.txt", "frame_0002.png", "line 3", "quaternion"});
  std::ofstream(tmp.path() / "images.txt") << "2 0 0 0 0 0 0 1 1 zero.png\n\n";
  ExpectInputError([&] { ReadColmapModel(tmp.path()); }, {"images.txt", "zero.png", "quaternion"});
  std::ofstream(tmp.path() / "images.txt") << "2 1 0 0 0 0 inf 1 1 inf.png\n\n";
  ExpectInputError([&] { ReadColmapModel(tmp.path()); }, {"images.txt", "inf.png", "translation"});
  std::ofstream(tmp.path() / "images.txt") << "2 1 0 0 x 0 0 1 1 word.png\n\n";
  ExpectInputError([&] { ReadColmapModel(tmp.path()); }, {"images.txt", "line 1", "QZ"});
}

TEST(ColmapModelBadInput, NonFinitePoseInBinaryNamesImage) {
  TempDir tmp;
  ColmapModel model = MakeModel();
  model.images[4].cam_from_world.rotation.coeffs()[1] = std::numeric_limits<double>::quiet_NaN();
  WriteColmapModelBinary(model, tmp.path());
  ExpectInputError([&] { ReadColmapModel(tmp.path()); }, {"images.bin", model.images[4].name, "quaternion"});
  model = MakeModel();
  model.images[2].cam_from_world.translation.y() = std::numeric_limits<double>::infinity();
  WriteColmapModelBinary(model, tmp.path());
  ExpectInputError([&] { ReadColmapModel(tmp.path()); }, {"images.bin", model.images[2].name, "translation"});
}

TEST(ColmapModelBadInput, UnknownCameraAndBadCameras) {
  TempDir tmp;
  ColmapModel model = MakeModel();
  model.images[0].camera_id = 999;
  WriteColmapModelBinary(model, tmp.path());
  ExpectInputError([&] { ReadColmapModel(tmp.path()); }, {"images.bin", "camera 999", model.images[0].name});
  WriteColmapModelText(model, tmp.path() / "text");
  ExpectInputError([&] { ReadColmapModel(tmp.path() / "text"); }, {"images.txt", "camera 999"});

  // Unsupported model (11 = RAD_TAN_THIN_PRISM_FISHEYE) in binary, unknown name in text, wrong parameter count.
  model = MakeModel();
  WriteColmapModelBinary(model, tmp.path());
  std::string cams = ReadBytes(tmp.path() / "cameras.bin");
  const std::int32_t unsupported = 11;
  std::memcpy(cams.data() + 8 + 4, &unsupported, 4);
  WriteBytes(tmp.path() / "cameras.bin", cams);
  ExpectInputError([&] { ReadColmapModel(tmp.path()); }, {"cameras.bin", "unsupported camera model id 11"});
  std::ofstream(tmp.path() / "text" / "cameras.txt") << "1 RAD_TAN_THIN_PRISM_FISHEYE 64 48 50 32 24 0.1\n";
  ExpectInputError([&] { ReadColmapModel(tmp.path() / "text"); }, {"cameras.txt", "line 1", "RAD_TAN_THIN_PRISM_FISHEYE"});
  std::ofstream(tmp.path() / "text" / "cameras.txt") << "1 PINHOLE 64 48 50 32 24\n";
  ExpectInputError([&] { ReadColmapModel(tmp.path() / "text"); }, {"cameras.txt", "line 1", "parameters"});
  std::ofstream(tmp.path() / "text" / "cameras.txt") << "1 PINHOLE 64 48 -50 50 32 24\n";
  ExpectInputError([&] { ReadColmapModel(tmp.path() / "text"); }, {"cameras.txt", "focal"});
}

TEST(ColmapModelBadInput, MissingFolderOrFiles) {
  TempDir tmp;
  ExpectInputError([&] { ReadColmapModel(tmp.path() / "nope"); }, {"nope", "does not exist"});
  ExpectInputError([&] { ReadColmapModel(tmp.path()); }, {tmp.path().string(), "not a COLMAP model"});
  ExpectInputError([&] { ReadColmapModelText(tmp.path()); }, {"cameras.txt"});
}

}  // namespace
}  // namespace lfrecon
