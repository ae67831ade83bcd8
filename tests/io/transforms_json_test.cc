#include "io/transforms_json.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <random>

#include "io/json_file.h"
#include "util/error.h"
#include "common/test_util.h"

namespace lfrecon {
namespace {

using testing::TempDir;
using testing::ExpectInputError;
namespace fs = std::filesystem;

std::vector<TransformsFrame> MakeFrames(const std::vector<Camera>& cameras, int n) {
  std::mt19937 rng(3);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<TransformsFrame> frames;
  for (int i = 0; i < n; ++i) {
    TransformsFrame f;
    f.file_path = "images/" + std::to_string(10000 + i) + ".png";
    f.camera = cameras[i % cameras.size()];
    Eigen::Quaterniond q(g(rng), g(rng), g(rng), g(rng));
    q.normalize();
    if (q.w() < 0) q.coeffs() *= -1;
    f.cam_from_world = Rigid3d(q, Eigen::Vector3d(g(rng), g(rng), g(rng)));
    frames.push_back(f);
  }
  return frames;
}

void ExpectFramesEqual(const std::vector<TransformsFrame>& a, const std::vector<TransformsFrame>& b) {
  ASSERT_EQ(a.size(), b.size());
  for (size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(a[i].file_path, b[i].file_path);
    EXPECT_EQ(a[i].camera.model, b[i].camera.model);
    EXPECT_EQ(a[i].camera.width, b[i].camera.width);
    EXPECT_EQ(a[i].camera.height, b[i].camera.height);
    ASSERT_EQ(a[i].camera.params.size(), b[i].camera.params.size());
    for (size_t k = 0; k < a[i].camera.params.size(); ++k)
      EXPECT_NEAR(a[i].camera.params[k], b[i].camera.params[k], 1e-12);
    const Eigen::Matrix<double, 3, 4> ma = a[i].cam_from_world.ToMatrix(),
                                      mb = b[i].cam_from_world.ToMatrix();
    EXPECT_LT((ma - mb).cwiseAbs().maxCoeff(), 1e-12) << i;
  }
}

nlohmann::json ReadJson(const fs::path& p) {
  std::ifstream in(p);
  return nlohmann::json::parse(in);
}

TEST(TransformsJson, RoundTripSharedIntrinsics) {
  TempDir tmp;
  const auto frames = MakeFrames({Camera::Pinhole(640, 360, 614.7, 615.2, 321.5, 179.25)}, 9);
  WriteTransformsJson(frames, tmp.path() / "transforms.json");
  const nlohmann::json j = ReadJson(tmp.path() / "transforms.json");
  EXPECT_TRUE(j.contains("fl_x"));
  EXPECT_FALSE(j["frames"][0].contains("fl_x"));
  EXPECT_FALSE(j.contains("k1"));
  ExpectFramesEqual(frames, ReadTransformsJson(tmp.path() / "transforms.json"));
}

TEST(TransformsJson, RoundTripPerFrameIntrinsicsWithDistortion) {
  TempDir tmp;
  Camera opencv;
  opencv.model = CameraModelId::kOpenCV;
  opencv.width = 800;
  opencv.height = 600;
  opencv.params = {700, 710, 401, 299, -0.12, 0.034, 0.0011, -0.0007};
  const auto frames = MakeFrames({Camera::Pinhole(640, 480, 500, 500, 320, 240), opencv}, 6);
  WriteTransformsJson(frames, tmp.path() / "t.json");
  const nlohmann::json j = ReadJson(tmp.path() / "t.json");
  EXPECT_FALSE(j.contains("fl_x"));
  EXPECT_TRUE(j["frames"][1].contains("k1"));
  ExpectFramesEqual(frames, ReadTransformsJson(tmp.path() / "t.json"));
}

// The OpenGL camera looks down its -z with +y up: in OpenCV axes its +z is world -z
// when transform_matrix is the identity.
TEST(TransformsJson, OpenGlToOpenCvAxes) {
  TempDir tmp;
  std::ofstream(tmp.path() / "t.json") << R"({"camera_angle_x": 1.0, "w": 200, "h": 100,
    "frames": [{"file_path": "a", "transform_matrix": [[1,0,0,1],[0,1,0,2],[0,0,1,3],[0,0,0,1]]}]})";
  const auto frames = ReadTransformsJson(tmp.path() / "t.json");
  ASSERT_EQ(frames.size(), 1u);
  const Rigid3d& pose = frames[0].cam_from_world;
  EXPECT_LT((CameraCenter(pose) - Eigen::Vector3d(1, 2, 3)).norm(), 1e-15);
  EXPECT_LT((ViewingDirection(pose) - Eigen::Vector3d(0, 0, -1)).norm(), 1e-15);
  // Image y (down) is world -y.
  EXPECT_LT((pose.rotation.inverse() * Eigen::Vector3d::UnitY() - Eigen::Vector3d(0, -1, 0)).norm(), 1e-15);
  const Camera& c = frames[0].camera;
  EXPECT_EQ(c.model, CameraModelId::kPinhole);
  EXPECT_NEAR(c.fx(), 100.0 / std::tan(0.5), 1e-12);
  EXPECT_NEAR(c.fy(), c.fx(), 0);
  EXPECT_EQ(c.cx(), 100.0);
  EXPECT_EQ(c.cy(), 50.0);
}

TEST(TransformsJson, PerFrameOverridesAndDistortion) {
  TempDir tmp;
  std::ofstream(tmp.path() / "t.json") << R"({"fl_x": 300, "fl_y": 310, "w": 200, "h": 100, "k1": 0, "p2": 0,
    "frames": [
      {"file_path": "a", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]},
      {"file_path": "b", "k1": -0.1, "cx": 99, "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0]]}]})";
  const auto frames = ReadTransformsJson(tmp.path() / "t.json");
  ASSERT_EQ(frames.size(), 2u);
  EXPECT_EQ(frames[0].camera.model, CameraModelId::kPinhole);  // zero distortion keeps PINHOLE
  EXPECT_EQ(frames[1].camera.model, CameraModelId::kOpenCV);
  EXPECT_EQ(frames[1].camera.params, (std::vector<double>{300, 310, 99, 50, -0.1, 0, 0, 0}));
}

TEST(TransformsJson, Figurines) {
  const fs::path path = fs::path(LFRECON_SHARED_DIR) / "data" / "figurines" / "transforms.json";
  if (!fs::exists(path)) GTEST_SKIP() << "figurines data set not found at " << path;
  const auto frames = ReadTransformsJson(path);
  ASSERT_EQ(frames.size(), 480u);
  EXPECT_EQ(frames[0].file_path, "images/00000.jpg");
  EXPECT_EQ(frames[0].camera.width, 640);
  EXPECT_EQ(frames[0].camera.height, 360);
  EXPECT_NEAR(frames[0].camera.fx(), 614.7142456753097, 1e-9);
  EXPECT_EQ(frames[0].camera.cx(), 320.0);
  // Camera 0 sits at the transform's translation.
  EXPECT_LT((CameraCenter(frames[0].cam_from_world) -
             Eigen::Vector3d(0.898563027381897, -0.0018130093812942505, 0.9624413251876831))
                .norm(),
            1e-12);
}

TEST(TransformsJsonBadInput, NamesFileAndField) {
  TempDir tmp;
  const fs::path p = tmp.path() / "transforms.json";
  ExpectInputError([&] { ReadTransformsJson(p); }, {"transforms.json", "cannot open"});
  std::ofstream(p) << "{ not json";
  ExpectInputError([&] { ReadTransformsJson(p); }, {"transforms.json", "JSON"});
  std::ofstream(p) << R"({"w": 10, "h": 10, "fl_x": 10, "frames": [{"file_path": "x.png"}]})";
  ExpectInputError([&] { ReadTransformsJson(p); },
                   {"transforms.json", "frames[0]", "x.png", "transform_matrix"});
  std::ofstream(p) << R"({"w": 10, "fl_x": 10, "frames": [{"file_path": "x.png",
      "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]})";
  ExpectInputError([&] { ReadTransformsJson(p); }, {"transforms.json", "h", "missing"});
  std::ofstream(p) << R"({"w": 10, "h": 10, "frames": [{"file_path": "x.png",
      "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]})";
  ExpectInputError([&] { ReadTransformsJson(p); }, {"transforms.json", "focal"});
  std::ofstream(p) << R"({"w": 10, "h": 10, "fl_x": 10, "frames": [{"file_path": "x.png",
      "transform_matrix": [[2,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]})";
  ExpectInputError([&] { ReadTransformsJson(p); }, {"transforms.json", "x.png", "not a rotation"});
  std::ofstream(p) << R"({"w": 10, "h": 10, "fl_x": 10, "frames": [{"file_path": "x.png",
      "transform_matrix": [[1,0,0,0],[0,1,0,"a"],[0,0,1,0],[0,0,0,1]]}]})";
  ExpectInputError([&] { ReadTransformsJson(p); }, {"transforms.json", "x.png", "non-number"});
}

// A value nested a million deep (the stack overflowed in nlohmann::json's
// recursive dump/copy of it): refused while parsing, naming the file.
TEST(TransformsJsonBadInput, DeepNestingIsAnInputErrorNotACrash) {
  TempDir tmp;
  const fs::path p = tmp.path() / "transforms.json";
  const int deep = 1000000;
  {
    std::ofstream f(p);
    f << R"({"h": 10, "fl_x": 10, "w": )" << std::string(deep, '[') << std::string(deep, ']')
      << R"(, "frames": [{"file_path": "x.png", "transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]})";
  }
  ExpectInputError([&] { ReadTransformsJson(p); }, {"transforms.json", "nested deeper than"});
  {
    std::ofstream f(p);  // objects too
    f << R"({"frames": [], "x": )";
    for (int i = 0; i < deep; ++i) f << R"({"a":)";
    f << "1" << std::string(deep, '}') << "}";
  }
  ExpectInputError([&] { ReadTransformsJson(p); }, {"transforms.json", "nested deeper than"});
  // At the limit it parses; one deeper is refused.
  auto nested = [&](int levels) {
    std::ofstream f(p);
    f << std::string(levels, '[') << std::string(levels, ']');
  };
  nested(kMaxJsonDepth);
  EXPECT_TRUE(ReadJsonFile(p).is_array());
  nested(kMaxJsonDepth + 1);
  ExpectInputError([&] { ReadJsonFile(p); }, {"transforms.json", "nested deeper than 64"});
}

// Error messages reach clients (the ingest daemon's replies, job status): they
// name the file and the field or position, never what the file holds beyond a
// short printable token. A secret pasted into a bad value is not repeated
// (it was: nlohmann's dump of the value, its "last read" bytes, the name).
TEST(TransformsJsonBadInput, ErrorsDoNotEchoTheFilesContents) {
  TempDir tmp;
  const fs::path p = tmp.path() / "transforms.json";
  const std::string secret = "sk_live_SECRET_4eC39HqLyjWDarjtT1zdp7dc";
  const std::string matrix = R"("transform_matrix": [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]])";
  auto expect_clean = [&](const std::string& text, const std::vector<std::string>& needles) {
    SCOPED_TRACE(text.substr(0, 80));
    std::ofstream(p, std::ios::binary) << text;
    std::vector<std::string> all = {"transforms.json"};
    all.insert(all.end(), needles.begin(), needles.end());
    ExpectInputError([&] { ReadTransformsJson(p); }, all);
    try {
      ReadTransformsJson(p);
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.find("SECRET"), std::string::npos) << what;
      EXPECT_LT(what.size(), p.string().size() + 300) << what;  // no copy of the file
      for (char c : what) EXPECT_TRUE(c >= 0x20 && c < 0x7f) << what;
    }
  };
  // A string (or an object) where a number belongs: its type, not its value.
  expect_clean(R"({"w": 10, "h": 10, "fl_x": ")" + secret + R"(", "frames": [{"file_path": "x.png", )" + matrix +
                   "}]}",
               {"fl_x", "must be a number", "string"});
  expect_clean(R"({"w": 10, "h": 10, "fl_x": {"key": ")" + secret + R"("}, "frames": [{"file_path": "x.png", )" +
                   matrix + "}]}",
               {"fl_x", "object"});
  expect_clean(R"({"w": 10, "h": 10, "fl_x": 10, "frames": [{"file_path": "x.png",
      "transform_matrix": [[1,0,0,0],[0,1,0,")" + secret + R"("],[0,0,1,0],[0,0,0,1]]}]})",
               {"x.png", "non-number", "string"});
  // A camera model name: quoted only when short and printable.
  expect_clean(R"({"w": 10, "h": 10, "fl_x": 10, "camera_model": ")" + secret + R"(", "frames": [{"file_path": "x.png", )" +
                   matrix + "}]}",
               {"camera_model", "unsupported camera model", "a text of 39 bytes"});
  expect_clean(R"({"w": 10, "h": 10, "fl_x": 10, "camera_model": "FISH\u0001EYE", "frames": [{"file_path": "x.png", )" +
                   matrix + "}]}",
               {"camera_model", "'FISH?EYE'"});
  // Not JSON: the position, not the bytes read (a raw newline inside a string).
  expect_clean("{\"w\": 10, \"fl_x\": \"" + secret + "\n\", \"frames\": []}", {"byte", "not valid JSON"});
  expect_clean("{\"w\": " + secret + "}", {"byte", "not valid JSON", "invalid literal"});
  // An image name that is the secret: not repeated in the frame's field.
  expect_clean(R"({"w": 10, "h": 10, "fl_x": 10, "frames": [{"file_path": ")" + secret + R"("}]})",
               {"frames[0]", "a text of 39 bytes", "transform_matrix"});
}

}  // namespace
}  // namespace lfrecon
