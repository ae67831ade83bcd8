#include "export/export.h"

#include <gtest/gtest.h>
#include <open3d/geometry/TriangleMesh.h>
#include <open3d/io/TriangleMeshIO.h>

#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>

#include "common/test_util.h"
#include "io/colmap_dense.h"
#include "io/colmap_model.h"

namespace lfrecon {
namespace {

using testing::TempDir;
namespace fs = std::filesystem;

// A coloured, non-symmetric mesh: a tetrahedron and a quad.
TriangleMesh SampleMesh() {
  TriangleMesh m;
  m.vertices = {{0.01f, 0.02f, 0.03f}, {0.31f, -0.05f, 0.1f}, {0.05f, 0.27f, -0.02f}, {0.1f, 0.1f, 0.4f},
                {1.f, 1.f, 0.f},      {1.5f, 1.f, 0.f},      {1.5f, 1.25f, 0.125f}, {1.f, 1.25f, 0.125f}};
  m.triangles = {{0, 2, 1}, {0, 1, 3}, {1, 2, 3}, {0, 3, 2}, {4, 5, 6}, {4, 6, 7}};
  for (int i = 0; i < 8; ++i) m.colors.push_back(Color3u8(30 * i, 255 - 30 * i, 17 * i));
  m.ComputeVertexNormals();
  return m;
}

// Same counts, and triangle t's corners at the same coordinates in the same
// order (a reader may number the vertices differently: Open3D's OBJ reader
// numbers them as the faces first use them).
void ExpectSameGeometry(const TriangleMesh& a, const open3d::geometry::TriangleMesh& b, double tol) {
  ASSERT_EQ(b.vertices_.size(), a.vertices.size());
  ASSERT_EQ(b.triangles_.size(), a.triangles.size());
  for (size_t t = 0; t < a.triangles.size(); ++t)
    for (int k = 0; k < 3; ++k)
      EXPECT_LT((b.vertices_[b.triangles_[t][k]] - a.vertices[a.triangles[t][k]].cast<double>()).norm(), tol)
          << "triangle " << t << " corner " << k;
}

std::string Base64Decode(const std::string& in) {
  std::string out;
  int val = 0, bits = -8;
  for (unsigned char c : in) {
    const char* table = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    const char* p = std::strchr(table, c);
    if (!p || c == 0) break;  // '=' padding ends the data
    val = (val << 6) + static_cast<int>(p - table);
    bits += 6;
    if (bits >= 0) {
      out.push_back(static_cast<char>((val >> bits) & 0xFF));
      bits -= 8;
    }
  }
  return out;
}

// A GLB's first mesh primitive: POSITION (float VEC3), COLOR_0 and the
// indices (unsigned short or int), from its JSON chunk and its buffer (a BIN
// chunk, or a base64 data URI as Open3D 0.16 writes it).
open3d::geometry::TriangleMesh ReadGlb(const fs::path& path) {
  std::ifstream f(path, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  const std::string b = ss.str();
  auto u32 = [&](std::size_t at) {
    std::uint32_t v;
    std::memcpy(&v, b.data() + at, 4);
    return v;
  };
  EXPECT_EQ(b.substr(0, 4), "glTF");
  EXPECT_EQ(u32(4), 2u);
  const std::uint32_t json_len = u32(12);
  const nlohmann::json j = nlohmann::json::parse(b.substr(20, json_len));
  std::string data;
  const auto& buffer = j["buffers"][0];
  if (buffer.contains("uri")) {
    const std::string uri = buffer["uri"].get<std::string>();
    data = Base64Decode(uri.substr(uri.find(',') + 1));
  } else {
    data = b.substr(20 + json_len + 8);
  }
  EXPECT_EQ(data.size(), buffer["byteLength"].get<std::size_t>());
  const std::size_t bin = 0;
  auto accessor_data = [&](int a, std::size_t* count, int* type) {
    const auto& acc = j["accessors"][a];
    const auto& view = j["bufferViews"][acc["bufferView"].get<int>()];
    *count = acc["count"].get<std::size_t>();
    *type = acc["componentType"].get<int>();
    return bin + view.value("byteOffset", std::size_t{0}) + acc.value("byteOffset", std::size_t{0});
  };
  const auto& prim = j["meshes"][0]["primitives"][0];
  open3d::geometry::TriangleMesh m;
  std::size_t n;
  int type;
  std::size_t at = accessor_data(prim["attributes"]["POSITION"].get<int>(), &n, &type);
  for (std::size_t i = 0; i < n; ++i) {
    float v[3];
    std::memcpy(v, data.data() + at + 12 * i, 12);
    m.vertices_.emplace_back(v[0], v[1], v[2]);
  }
  if (prim["attributes"].contains("COLOR_0")) {
    at = accessor_data(prim["attributes"]["COLOR_0"].get<int>(), &n, &type);
    for (std::size_t i = 0; i < n; ++i) {
      float v[3];
      std::memcpy(v, data.data() + at + 12 * i, 12);
      m.vertex_colors_.emplace_back(v[0], v[1], v[2]);
    }
  }
  at = accessor_data(prim["indices"].get<int>(), &n, &type);
  std::vector<int> idx;
  for (std::size_t i = 0; i < n; ++i) {
    if (type == 5123) {
      std::uint16_t v;
      std::memcpy(&v, data.data() + at + 2 * i, 2);
      idx.push_back(v);
    } else {
      std::uint32_t v;
      std::memcpy(&v, data.data() + at + 4 * i, 4);
      idx.push_back(static_cast<int>(v));
    }
  }
  for (std::size_t t = 0; t + 2 < idx.size(); t += 3) m.triangles_.emplace_back(idx[t], idx[t + 1], idx[t + 2]);
  return m;
}

TEST(WriteMeshFile, ObjReadBackByOpen3DAndGlbParsed) {
  TempDir tmp;
  const TriangleMesh mesh = SampleMesh();
  for (const char* name : {"mesh.obj", "mesh.glb"}) {
    const fs::path p = tmp.path() / name;
    WriteMeshFile(mesh, p);
    open3d::geometry::TriangleMesh back;
    if (std::string(name) == "mesh.obj") {
      ASSERT_TRUE(open3d::io::ReadTriangleMesh(p.string(), back));
    } else {
      // Debian's Open3D 0.16 does not read GLB back (ReadTriangleMesh goes to ASSIMP, which
      // fails; ReadTriangleMeshFromGLTF: "unable to open file"): the chunks are parsed here.
      back = ReadGlb(p);
    }
    ExpectSameGeometry(mesh, back, 2e-6);  // OBJ: 6 decimals
    ASSERT_TRUE(back.HasVertexColors()) << name;
    for (size_t t = 0; t < mesh.triangles.size(); ++t) {
      const int i = mesh.triangles[t][0], j = back.triangles_[t][0];
      EXPECT_LT((back.vertex_colors_[j] - mesh.colors[i].cast<double>() / 255.0).norm(), 1e-3) << name;
    }
  }
  WriteMeshFile(mesh, tmp.path() / "mesh.ply");
  open3d::geometry::TriangleMesh ply;
  ASSERT_TRUE(open3d::io::ReadTriangleMesh((tmp.path() / "mesh.ply").string(), ply));
  ExpectSameGeometry(mesh, ply, 1e-7);
  testing::ExpectInputError([&] { WriteMeshFile(mesh, tmp.path() / "mesh.stl"); }, {"mesh.stl", "unsupported"});
}

// Beyond 65535 vertices the GLB's indices must be 32-bit.
TEST(WriteMeshFile, LargeGlbKeepsEveryIndex) {
  TempDir tmp;
  TriangleMesh mesh;
  const int side = 300;  // 90000 vertices
  for (int y = 0; y < side; ++y)
    for (int x = 0; x < side; ++x) mesh.vertices.emplace_back(0.001f * x, 0.001f * y, 0.0001f * ((x * y) % 7));
  for (int y = 0; y + 1 < side; ++y)
    for (int x = 0; x + 1 < side; ++x) {
      const int i = y * side + x;
      mesh.triangles.emplace_back(i, i + 1, i + side);
      mesh.triangles.emplace_back(i + 1, i + side + 1, i + side);
    }
  WriteMeshFile(mesh, tmp.path() / "big.glb");
  ExpectSameGeometry(mesh, ReadGlb(tmp.path() / "big.glb"), 1e-7);
}

TEST(ColmapDenseMap, LayoutIsHeaderThenChannelPlanesRowMajor) {
  TempDir tmp;
  cv::Mat m(2, 3, CV_32FC3);
  for (int r = 0; r < 2; ++r)
    for (int c = 0; c < 3; ++c) m.at<cv::Vec3f>(r, c) = cv::Vec3f(r * 10 + c, 100 + r * 10 + c, 200 + r * 10 + c);
  const fs::path p = tmp.path() / "a.png.geometric.bin";
  WriteColmapDenseMap(p, m);
  std::ifstream f(p, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  const std::string bytes = ss.str();
  const std::string header = "3&2&3&";
  ASSERT_EQ(bytes.size(), header.size() + 18 * sizeof(float));
  EXPECT_EQ(bytes.substr(0, header.size()), header);
  std::vector<float> v(18);
  std::memcpy(v.data(), bytes.data() + header.size(), v.size() * sizeof(float));
  // value (row, col, ch) at ch * W * H + row * W + col, as COLMAP's Mat<float>::Get
  for (int ch = 0; ch < 3; ++ch)
    for (int r = 0; r < 2; ++r)
      for (int c = 0; c < 3; ++c) EXPECT_EQ(v[ch * 6 + r * 3 + c], ch * 100 + r * 10 + c);
  const cv::Mat back = ReadColmapDenseMap(p);
  ASSERT_EQ(back.type(), CV_32FC3);
  EXPECT_EQ(cv::norm(back, m, cv::NORM_INF), 0.0);
  std::ofstream(tmp.path() / "bad.bin") << "3&2&1&abc";
  testing::ExpectInputError([&] { ReadColmapDenseMap(tmp.path() / "bad.bin"); }, {"bad.bin", "data ends"});
  std::ofstream(tmp.path() / "bad2.bin") << "99999&99999&4&";
  testing::ExpectInputError([&] { ReadColmapDenseMap(tmp.path() / "bad2.bin"); }, {"bad2.bin", "out of range"});
}

// A camera looking down +z at the plane z = 2 - 0.5 x (world = camera frame).
struct PlaneScene {
  PinholeView view = PinholeView(Camera::Pinhole(40, 30, 35, 35, 20, 15), Rigid3d());
  cv::Mat depth = cv::Mat(30, 40, CV_32F);  // not {..}: that is Mat's initializer-list constructor
  PlaneScene() {
    for (int r = 0; r < 30; ++r)
      for (int c = 0; c < 40; ++c) {
        const Eigen::Vector3d ray = view.K_inv * Eigen::Vector3d(c + 0.5, r + 0.5, 1);  // z = 1
        depth.at<float>(r, c) = static_cast<float>(2.0 / (1.0 + 0.5 * ray.x()));         // z = 2 - 0.5 x
      }
  }
};

TEST(NormalsFromDepth, PlaneNormalFacingTheCamera) {
  const PlaneScene s;
  const cv::Mat n = NormalsFromDepth(s.view, s.depth);
  const Eigen::Vector3d expect = -Eigen::Vector3d(0.5, 0, 1).normalized();
  const cv::Vec3f got = n.at<cv::Vec3f>(15, 20);
  EXPECT_LT((Eigen::Vector3d(got[0], got[1], got[2]) - expect).norm(), 1e-4);
  EXPECT_EQ(n.at<cv::Vec3f>(1, 1), cv::Vec3f(0, 0, 0));  // border: no neighbours two pixels away
}

TEST(PointCloudFromDepthMaps, PointsOnThePlaneThinnedPerVoxel) {
  const PlaneScene s;
  BoundingBox all;
  all.min = Eigen::Vector3d::Constant(-10);
  all.max = Eigen::Vector3d::Constant(10);
  const TriangleMesh dense = PointCloudFromDepthMaps({s.view}, {s.depth}, {}, all, 0);
  EXPECT_EQ(dense.vertices.size(), 1200u);
  const TriangleMesh thin = PointCloudFromDepthMaps({s.view}, {s.depth}, {cv::Mat(30, 40, CV_32FC3, cv::Scalar(0, 0.5, 1))},
                                                    all, 0.1);
  EXPECT_LT(thin.vertices.size(), dense.vertices.size() / 2);
  EXPECT_GT(thin.vertices.size(), 20u);
  ASSERT_TRUE(thin.HasColors());
  EXPECT_EQ(thin.colors[0], Color3u8(255, 128, 0));  // RGB from BGR
  for (const auto& p : thin.vertices) EXPECT_NEAR(p.z(), 2 - 0.5 * p.x(), 2e-3);  // centroids of plane points
  BoundingBox half = all;
  half.max.x() = 0;
  EXPECT_LT(PointCloudFromDepthMaps({s.view}, {s.depth}, {}, half, 0).vertices.size(), 700u);
}

TEST(WriteColmapWorkspace, LayoutColmapReads) {
  TempDir tmp;
  const PlaneScene s;
  cv::Mat depth = s.depth.clone();
  depth.at<float>(3, 3) = std::nanf("");
  const auto names = WriteColmapWorkspace(
      tmp.path(), {{"sub/00001.jpg", s.view, cv::Mat(30, 40, CV_32FC3, cv::Scalar(0.2, 0.4, 0.6)), depth}});
  ASSERT_EQ(names, std::vector<std::string>{"sub_00001.jpg.png"});
  EXPECT_TRUE(fs::exists(tmp.path() / "images" / "sub_00001.jpg.png"));
  const cv::Mat d = ReadColmapDenseMap(tmp.path() / "stereo/depth_maps/sub_00001.jpg.png.geometric.bin");
  EXPECT_EQ(d.at<float>(3, 3), 0.f);  // no depth is 0 for COLMAP
  EXPECT_EQ(d.at<float>(10, 10), s.depth.at<float>(10, 10));
  EXPECT_EQ(ReadColmapDenseMap(tmp.path() / "stereo/normal_maps/sub_00001.jpg.png.geometric.bin").channels(), 3);
  const ColmapModel model = ReadColmapModel(tmp.path() / "sparse");
  ASSERT_EQ(model.images.size(), 1u);
  EXPECT_EQ(model.images[0].name, "sub_00001.jpg.png");
  EXPECT_EQ(model.cameras.at(1).model, CameraModelId::kPinhole);
  std::ifstream cfg(tmp.path() / "stereo" / "fusion.cfg");
  std::string line;
  std::getline(cfg, line);
  EXPECT_EQ(line, "sub_00001.jpg.png");
}

}  // namespace
}  // namespace lfrecon
