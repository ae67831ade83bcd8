#include "io/ply.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <fstream>
#include <functional>
#include <random>

#include "util/error.h"
#include "common/test_util.h"

namespace lfrecon {
namespace {

using testing::TempDir;
using testing::ExpectInputError;
namespace fs = std::filesystem;

TriangleMesh RandomMesh(int num_vertices, int num_triangles, bool normals, bool colors) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-2.f, 2.f);
  std::uniform_int_distribution<int> vi(0, num_vertices - 1), ci(0, 255);
  TriangleMesh m;
  for (int i = 0; i < num_vertices; ++i) {
    m.vertices.emplace_back(u(rng), u(rng), u(rng));
    if (normals) m.normals.push_back(Eigen::Vector3f(u(rng), u(rng), u(rng)).normalized());
    if (colors) m.colors.emplace_back(ci(rng), ci(rng), ci(rng));
  }
  for (int t = 0; t < num_triangles; ++t) m.triangles.emplace_back(vi(rng), vi(rng), vi(rng));
  return m;
}

void ExpectMeshesEqual(const TriangleMesh& a, const TriangleMesh& b) {
  ASSERT_EQ(a.vertices.size(), b.vertices.size());
  ASSERT_EQ(a.normals.size(), b.normals.size());
  ASSERT_EQ(a.colors.size(), b.colors.size());
  ASSERT_EQ(a.triangles.size(), b.triangles.size());
  for (size_t i = 0; i < a.vertices.size(); ++i) {
    EXPECT_EQ(a.vertices[i], b.vertices[i]) << i;
    if (!a.normals.empty()) {
      EXPECT_EQ(a.normals[i], b.normals[i]) << i;
    }
    if (!a.colors.empty()) {
      EXPECT_EQ(a.colors[i], b.colors[i]) << i;
    }
  }
  for (size_t t = 0; t < a.triangles.size(); ++t) EXPECT_EQ(a.triangles[t], b.triangles[t]) << t;
}

TEST(Ply, BinaryRoundTripWithNormalsAndColours) {
  TempDir tmp;
  const TriangleMesh mesh = RandomMesh(500, 900, true, true);
  WritePly(mesh, tmp.path() / "m.ply");
  const TriangleMesh read = ReadPly(tmp.path() / "m.ply");
  EXPECT_TRUE(read.HasNormals());
  EXPECT_TRUE(read.HasColors());
  ExpectMeshesEqual(mesh, read);
  // Header says binary little-endian.
  std::ifstream in(tmp.path() / "m.ply", std::ios::binary);
  std::string line;
  std::getline(in, line);
  std::getline(in, line);
  EXPECT_EQ(line, "format binary_little_endian 1.0");
}

TEST(Ply, BinaryRoundTripPointCloud) {
  TempDir tmp;
  const TriangleMesh cloud = RandomMesh(77, 0, false, true);
  WritePly(cloud, tmp.path() / "c.ply");
  const TriangleMesh read = ReadPly(tmp.path() / "c.ply");
  EXPECT_FALSE(read.HasNormals());
  ExpectMeshesEqual(cloud, read);
  std::ifstream in(tmp.path() / "c.ply", std::ios::binary);
  const std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  EXPECT_EQ(all.find("element face"), std::string::npos);
}

TEST(Ply, AsciiPolygonsAreFanned) {
  TempDir tmp;
  std::ofstream(tmp.path() / "q.ply")
      << "ply\r\nformat ascii 1.0\r\ncomment quad and triangle\r\n"
         "element vertex 5\r\nproperty double x\r\nproperty double y\r\n"
         "property double z\r\nproperty float nx\r\nproperty float ny\r\n"
         "property float nz\r\nproperty uchar red\r\nproperty uchar green\r\n"
         "property uchar blue\r\nproperty uchar alpha\r\n"
         "element face 2\r\nproperty list int uint vertex_indices\r\n"
         "end_header\r\n"
         "0 0 0 0 0 1 255 0 0 255\n1 0 0 0 0 1 0 255 0 255\n1 1 0 0 0 1 0 0 255 255\n"
         "0 1 0 0 0 1 10 20 30 255\n0.5 0.5 1.5 0 0 1 1 2 3 4\n"
         "4 0 1 2 3\n3 4 0 1\n";
  const TriangleMesh m = ReadPly(tmp.path() / "q.ply");
  ASSERT_EQ(m.vertices.size(), 5u);
  ASSERT_TRUE(m.HasNormals());
  ASSERT_TRUE(m.HasColors());
  EXPECT_EQ(m.vertices[4], Eigen::Vector3f(0.5f, 0.5f, 1.5f));
  EXPECT_EQ(m.colors[3], Color3u8(10, 20, 30));
  ASSERT_EQ(m.triangles.size(), 3u);
  EXPECT_EQ(m.triangles[0], Eigen::Vector3i(0, 1, 2));
  EXPECT_EQ(m.triangles[1], Eigen::Vector3i(0, 2, 3));
  EXPECT_EQ(m.triangles[2], Eigen::Vector3i(4, 0, 1));
}

TEST(Ply, BinaryDoublesIntCountsUintIndicesAndExtraElements) {
  TempDir tmp;
  std::string body;
  auto put = [&](const auto& v) { body.append(reinterpret_cast<const char*>(&v), sizeof(v)); };
  for (int i = 0; i < 4; ++i) {
    put(double(i));
    put(double(2 * i));
    put(double(-i));
    put(float(0.25f * i));  // an extra property to skip
  }
  put(std::int32_t(4));
  for (std::uint32_t k : {3u, 2u, 1u, 0u}) put(k);
  put(std::uint8_t(7));   // a per-face property after the list
  put(std::int16_t(-3));  // an "edge" element entry to skip
  const std::string header =
      "ply\nformat binary_little_endian 1.0\nelement vertex 4\nproperty double x\nproperty double y\n"
      "property double z\nproperty float quality\nelement face 1\nproperty list int uint vertex_indices\n"
      "property uchar flags\nelement edge 1\nproperty short e\nend_header\n";
  std::ofstream(tmp.path() / "d.ply", std::ios::binary) << header << body;
  const TriangleMesh m = ReadPly(tmp.path() / "d.ply");
  ASSERT_EQ(m.vertices.size(), 4u);
  EXPECT_EQ(m.vertices[3], Eigen::Vector3f(3, 6, -3));
  EXPECT_FALSE(m.HasNormals());
  ASSERT_EQ(m.triangles.size(), 2u);
  EXPECT_EQ(m.triangles[0], Eigen::Vector3i(3, 2, 1));
  EXPECT_EQ(m.triangles[1], Eigen::Vector3i(3, 1, 0));
}

TEST(Ply, BinaryBigEndian) {
  TempDir tmp;
  std::string body;
  auto put = [&](auto v) {
    char* b = reinterpret_cast<char*>(&v);
    std::reverse(b, b + sizeof(v));
    body.append(b, sizeof(v));
  };
  for (float v : {1.f, 2.f, 3.f, 4.f, 5.f, 6.f, -7.f, 8.f, 9.f}) put(v);
  put(std::uint16_t(3));
  for (std::int32_t k : {2, 0, 1}) put(k);
  std::ofstream(tmp.path() / "be.ply", std::ios::binary)
      << "ply\nformat binary_big_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
         "property float z\nelement face 1\nproperty list ushort int vertex_indices\nend_header\n"
      << body;
  const TriangleMesh m = ReadPly(tmp.path() / "be.ply");
  ASSERT_EQ(m.vertices.size(), 3u);
  EXPECT_EQ(m.vertices[2], Eigen::Vector3f(-7, 8, 9));
  ASSERT_EQ(m.triangles.size(), 1u);
  EXPECT_EQ(m.triangles[0], Eigen::Vector3i(2, 0, 1));
}

TEST(Ply, FigurinesGroundTruthAscii) {
  const fs::path root = fs::path(LFRECON_SHARED_DIR) / "data" / "figurines";
  if (!fs::exists(root / "gt_mesh.ply")) GTEST_SKIP() << "figurines data set not found at " << root;
  const TriangleMesh m = ReadPly(root / "gt_mesh.ply");
  EXPECT_EQ(m.vertices.size(), 4714u);
  EXPECT_EQ(m.triangles.size(), 9668u);
  Eigen::Vector3f lo, hi;
  m.Bounds(&lo, &hi);
  // Inside scene.json's foreground box (metres), with a little slack.
  EXPECT_GT(lo.minCoeff(), -0.27f);
  EXPECT_GT(lo.z(), -1e-4f);
  EXPECT_LT(hi.x(), 0.28f);
  EXPECT_LT(hi.z(), 0.46f);
  EXPECT_GT(m.SurfaceArea(), 0.01);
  const TriangleMesh thin = ReadPly(root / "gt_thin.ply");
  EXPECT_EQ(thin.vertices.size(), 4714u);
  EXPECT_EQ(thin.triangles.size(), 1972u);
}

TEST(PlyBadInput, TruncatedAndCorrupt) {
  TempDir tmp;
  const fs::path p = tmp.path() / "m.ply";
  ExpectInputError([&] { ReadPly(p); }, {"m.ply", "does not exist"});
  WritePly(RandomMesh(50, 60, true, true), p);
  std::ifstream in(p, std::ios::binary);
  const std::string full((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const size_t header_end = full.find("end_header\n") + 11;
  for (size_t cut :
       {size_t(10), header_end - 3, header_end, header_end + 5, full.size() / 2, full.size() - 1}) {
    std::ofstream(p, std::ios::binary) << full.substr(0, cut);
    SCOPED_TRACE(cut);
    ExpectInputError([&] { ReadPly(p); }, {"m.ply"});
  }
  // A huge count must not allocate.
  std::string huge = full;
  const size_t at = huge.find("element vertex 50");
  huge.replace(at, 17, "element vertex 999999999999");
  std::ofstream(p, std::ios::binary) << huge;
  ExpectInputError([&] { ReadPly(p); }, {"m.ply", "element vertex"});
  std::ofstream(p) << "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                      "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
                      "0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n";
  ExpectInputError([&] { ReadPly(p); }, {"m.ply", "face 0", "vertex index"});
  std::ofstream(p) << "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                      "property float z\nend_header\n0 zero 0\n";
  ExpectInputError([&] { ReadPly(p); }, {"m.ply", "vertex 0", "zero"});
  std::ofstream(p) << "solid stl\n";
  ExpectInputError([&] { ReadPly(p); }, {"m.ply", "not a PLY"});
}

// Tokens of the file quoted in errors (a bad value, a header keyword, an
// element name) came out raw: binary bytes and any length. Now the error
// names the file and position and quotes at most a short printable token.
TEST(PlyBadInput, ErrorsDoNotEchoBinaryOrHugeTokens) {
  TempDir tmp;
  const fs::path p = tmp.path() / "t.ply";
  const std::string binary("\x1b[2J\x01\xff", 6);  // a terminal escape and two control bytes
  const std::string huge = "SECRET" + std::string(10000, 'x');      // 10 kB without white space
  const std::string header = "ply\nformat ascii 1.0\n";
  const std::string vertex = "element vertex 1\nproperty float x\nproperty float y\nproperty float z\n";
  using testing::ExpectInputErrorWithoutEcho;
  auto expect = [&](const std::string& bytes, const std::vector<std::string>& needles) {
    std::ofstream(p, std::ios::binary) << bytes;
    ExpectInputErrorWithoutEcho([&] { ReadPly(p); }, needles, {"SECRET", "xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx"});
  };
  // A value: the ASCII body.
  expect(header + vertex + "end_header\n0 " + huge + " 0\n", {"t.ply", "vertex 0", "10006 bytes", "not a number"});
  expect(header + vertex + "end_header\n0 \x01\x02\x03\xfe 0\n", {"t.ply", "vertex 0", "'????'"});
  // The header's keywords, format, types and element lines.
  expect("ply\nformat " + huge + " 1.0\n" + vertex + "end_header\n", {"t.ply", "header line 2", "unknown format"});
  expect("ply\nformat " + binary + " 1.0\n" + vertex + "end_header\n",
         {"t.ply", "header line 2", "unknown format '?[2J??'"});
  expect(header + huge + "\n" + vertex + "end_header\n", {"t.ply", "header line 3", "unexpected header keyword"});
  expect(header + "element v " + huge + "\nend_header\n", {"t.ply", "header line 3", "malformed element line"});
  expect(header + vertex + "property " + huge + " w\nend_header\n",
         {"t.ply", "header line 7", "unknown property type"});
  expect(header + vertex + "property list " + huge + " int i\nend_header\n",
         {"t.ply", "header line 7", "malformed list property"});
  // An element's name in the field: more entries promised than the bytes left can hold.
  expect(header + vertex + "element " + huge + " 2\nproperty list uchar int i\nend_header\n0 0 0\n",
         {"t.ply", "element a text of 10006 bytes"});
  expect(header + vertex + "element e\x1b\x07 99\nproperty float a\nend_header\n0 0 0\n1\n",
         {"t.ply", "element 'e??'"});
}

// `f` in a child process: its exit code (0: InputError naming every needle; 1: other
// outcome), or -1 if it did not finish within `seconds` (it is killed).
int InputErrorWithin(const std::function<void()>& f, const std::vector<std::string>& needles, double seconds) {
  const pid_t pid = ::fork();
  if (pid == 0) {
    int code = 1;
    try {
      f();
    } catch (const InputError& e) {
      code = 0;
      for (const std::string& n : needles) code |= std::string(e.what()).find(n) == std::string::npos;
    } catch (...) {
    }
    ::_exit(code);
  }
  int status = 0;
  for (int i = 0; i < seconds * 100; ++i) {
    if (::waitpid(pid, &status, WNOHANG) == pid) return WIFEXITED(status) ? WEXITSTATUS(status) : 1;
    ::usleep(10000);
  }
  ::kill(pid, SIGKILL);
  ::waitpid(pid, &status, 0);
  return -1;
}

// An element without properties takes no bytes, so its count is bounded by
// nothing: 2^64-1 of them kept the reader looping for ever. Refused at once.
TEST(PlyBadInput, ElementWithoutPropertiesAndHugeCount) {
  TempDir tmp;
  const fs::path p = tmp.path() / "e.ply";
  for (const char* format : {"ascii", "binary_little_endian"}) {
    SCOPED_TRACE(format);
    std::ofstream(p, std::ios::binary) << "ply\nformat " << format
                                       << " 1.0\nelement empty 18446744073709551615\nelement vertex 1\n"
                                          "property float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n";
    EXPECT_EQ(InputErrorWithin([&] { ReadPly(p); }, {"e.ply", "element empty", "no properties"}, 5), 0);
  }
  // A count of 0 without properties is harmless.
  std::ofstream(p) << "ply\nformat ascii 1.0\nelement empty 0\nelement vertex 1\nproperty float x\n"
                      "property float y\nproperty float z\nend_header\n1 2 3\n";
  EXPECT_EQ(ReadPly(p).vertices.size(), 1u);
}

}  // namespace
}  // namespace lfrecon
