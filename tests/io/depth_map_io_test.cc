#include "io/depth_map_io.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>

#include "util/error.h"
#include "common/test_util.h"

namespace lfrecon {
namespace {

using testing::TempDir;
using testing::ExpectInputError;
namespace fs = std::filesystem;

// Non-square, with zeros, tiny and huge values, so that flips and precision loss show.
cv::Mat RandomDepth(int rows, int cols) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.3f, 7.f);
  cv::Mat m(rows, cols, CV_32F);
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) m.at<float>(r, c) = (r * 7 + c) % 11 == 0 ? 0.f : u(rng) + r * 1e-3f;
  m.at<float>(0, 0) = 1e-30f;
  m.at<float>(rows - 1, cols - 1) = 3.0e30f;
  m.at<float>(0, cols - 1) = -2.5f;
  return m;
}

bool BitEqual(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  for (int r = 0; r < a.rows; ++r)
    if (std::memcmp(a.ptr(r), b.ptr(r), a.cols * a.elemSize()) != 0) return false;
  return true;
}

TEST(DepthMapIo, PfmRoundTripIsExactAndBottomUp) {
  TempDir tmp;
  const cv::Mat depth = RandomDepth(23, 37);
  WritePfm(tmp.path() / "d.pfm", depth);
  const cv::Mat read = ReadPfm(tmp.path() / "d.pfm");
  EXPECT_TRUE(BitEqual(depth, read));
  EXPECT_TRUE(BitEqual(depth, ReadDepthMap(tmp.path() / "d.pfm")));
  // The file's first stored row is the image's bottom row.
  std::ifstream in(tmp.path() / "d.pfm", std::ios::binary);
  const std::string all((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string header = "Pf\n37 23\n-1\n";
  ASSERT_EQ(all.substr(0, header.size()), header);
  ASSERT_EQ(all.size(), header.size() + 23 * 37 * 4);
  float first;
  std::memcpy(&first, all.data() + header.size(), 4);
  EXPECT_EQ(first, depth.at<float>(22, 0));
}

TEST(DepthMapIo, PfmBigEndianAndColour) {
  TempDir tmp;
  // Big-endian 2x1 grayscale written by hand: rows bottom-to-top, one row here.
  std::string data = "Pf\n2 1\n1.0\n";
  for (float v : {1.5f, -2.25f}) {
    char b[4];
    std::memcpy(b, &v, 4);
    std::reverse(b, b + 4);
    data.append(b, 4);
  }
  std::ofstream(tmp.path() / "be.pfm", std::ios::binary) << data;
  const cv::Mat be = ReadPfm(tmp.path() / "be.pfm");
  ASSERT_EQ(be.size(), cv::Size(2, 1));
  EXPECT_EQ(be.at<float>(0, 0), 1.5f);
  EXPECT_EQ(be.at<float>(0, 1), -2.25f);

  cv::Mat colour(5, 4, CV_32FC3);
  cv::randu(colour, cv::Scalar::all(0), cv::Scalar::all(1));
  WritePfm(tmp.path() / "c.pfm", colour);
  EXPECT_TRUE(BitEqual(colour, ReadPfm(tmp.path() / "c.pfm")));
}

TEST(DepthMapIo, ExrRoundTripIsExact) {
  TempDir tmp;
  const cv::Mat depth = RandomDepth(31, 45);
  WriteExr(tmp.path() / "d.exr", depth);
  const cv::Mat read = ReadExr(tmp.path() / "d.exr");
  EXPECT_EQ(read.type(), CV_32FC1);
  EXPECT_TRUE(BitEqual(depth, read));
  EXPECT_TRUE(BitEqual(depth, ReadDepthMap(tmp.path() / "d.exr")));
}

TEST(DepthMapIo, ExrMultiChannelKeepsFirst) {
  TempDir tmp;
  cv::Mat bgr(6, 7, CV_32FC3, cv::Scalar(1.25, 2.5, 3.75));
  EnableOpenCvExr();
  ASSERT_TRUE(cv::imwrite((tmp.path() / "c.exr").string(), bgr));
  const cv::Mat read = ReadExr(tmp.path() / "c.exr");
  ASSERT_EQ(read.type(), CV_32FC1);
  EXPECT_EQ(read.at<float>(3, 3), 1.25f);
}

TEST(DepthMapIo, FigurinesGroundTruthDepthIsPlausible) {
  const fs::path depth_dir = fs::path(LFRECON_SHARED_DIR) / "data" / "figurines" / "depth";
  if (!fs::exists(depth_dir / "depth_0000.exr"))
    GTEST_SKIP() << "figurines data set not found at " << depth_dir;
  for (const char* name : {"depth_0000.exr", "depth_0240.exr"}) {
    const cv::Mat d = ReadExr(depth_dir / name);
    ASSERT_EQ(d.type(), CV_32FC1) << name;
    ASSERT_EQ(d.size(), cv::Size(640, 360)) << name;
    std::vector<float> valid;
    for (int r = 0; r < d.rows; ++r)
      for (int c = 0; c < d.cols; ++c) {
        const float v = d.at<float>(r, c);
        if (std::isfinite(v) && v > 0 && v < 100) valid.push_back(v);
      }
    // Every pixel sees the table or the figurines.
    EXPECT_GT(valid.size(), 0.99 * d.total()) << name;
    std::sort(valid.begin(), valid.end());
    const float p1 = valid[valid.size() / 100], p50 = valid[valid.size() / 2],
                p99 = valid[valid.size() * 99 / 100];
    // The figurines are ~1.3 m from the camera; the far clutter reaches ~5.8 m.
    EXPECT_GT(p1, 0.5f) << name;
    EXPECT_LT(p99, 8.0f) << name;
    EXPECT_GT(p50, 0.5f) << name;
    EXPECT_LT(p50, 2.5f) << name;
  }
}

TEST(DepthMapIo, ColorizeMapAndPreview) {
  TempDir tmp;
  cv::Mat map(10, 20, CV_32F);
  for (int r = 0; r < 10; ++r)
    for (int c = 0; c < 20; ++c) map.at<float>(r, c) = 1.0f + c;  // 1 .. 20
  map.at<float>(5, 5) = 0.f;
  map.at<float>(6, 6) = std::numeric_limits<float>::quiet_NaN();
  const cv::Mat colored = ColorizeMap(map);
  ASSERT_EQ(colored.type(), CV_8UC3);
  EXPECT_EQ(colored.at<cv::Vec3b>(5, 5), cv::Vec3b(0, 0, 0));
  EXPECT_EQ(colored.at<cv::Vec3b>(6, 6), cv::Vec3b(0, 0, 0));
  // Auto range: the smallest value takes turbo's first colour, the largest its last.
  cv::Mat ends(1, 2, CV_8U);
  ends.at<std::uint8_t>(0, 0) = 0;
  ends.at<std::uint8_t>(0, 1) = 255;
  cv::Mat turbo;
  cv::applyColorMap(ends, turbo, cv::COLORMAP_TURBO);
  EXPECT_EQ(colored.at<cv::Vec3b>(0, 0), turbo.at<cv::Vec3b>(0, 0));
  EXPECT_EQ(colored.at<cv::Vec3b>(0, 19), turbo.at<cv::Vec3b>(0, 1));
  // An explicit range clamps.
  const cv::Mat clamped = ColorizeMap(map, 5.0, 10.0);
  EXPECT_EQ(clamped.at<cv::Vec3b>(0, 0), turbo.at<cv::Vec3b>(0, 0));
  EXPECT_EQ(clamped.at<cv::Vec3b>(0, 15), turbo.at<cv::Vec3b>(0, 1));

  cv::Mat frame(10, 15, CV_32FC3, cv::Scalar(0.0, 0.5, 1.0));
  WriteDepthPreview(tmp.path() / "p.png", map, frame);
  const cv::Mat png = cv::imread((tmp.path() / "p.png").string(), cv::IMREAD_UNCHANGED);
  ASSERT_EQ(png.size(), cv::Size(35, 10));
  EXPECT_EQ(png.at<cv::Vec3b>(2, 3), cv::Vec3b(0, 128, 255));
  EXPECT_EQ(png.at<cv::Vec3b>(5, 15 + 5), cv::Vec3b(0, 0, 0));
  EXPECT_EQ(png.at<cv::Vec3b>(0, 15 + 19), turbo.at<cv::Vec3b>(0, 1));
}

TEST(DepthMapIoBadInput, NamesTheFile) {
  TempDir tmp;
  const fs::path pfm = tmp.path() / "bad.pfm";
  ExpectInputError([&] { ReadPfm(pfm); }, {"bad.pfm"});
  WritePfm(pfm, RandomDepth(8, 9));
  std::ifstream in(pfm, std::ios::binary);
  const std::string full((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  for (size_t cut : {size_t(0), size_t(2), size_t(5), size_t(11), full.size() / 2, full.size() - 1}) {
    std::ofstream(pfm, std::ios::binary) << full.substr(0, cut);
    SCOPED_TRACE(cut);
    ExpectInputError([&] { ReadPfm(pfm); }, {"bad.pfm"});
  }
  std::ofstream(pfm, std::ios::binary) << "Pf\n100000000 100000000\n-1\n" << std::string(64, '\0');
  ExpectInputError([&] { ReadPfm(pfm); }, {"bad.pfm"});

  const fs::path exr = tmp.path() / "bad.exr";
  ExpectInputError([&] { ReadExr(exr); }, {"bad.exr", "does not exist"});
  std::ofstream(exr, std::ios::binary) << "this is not an EXR file at all, just bytes";
  ExpectInputError([&] { ReadExr(exr); }, {"bad.exr"});
  ExpectInputError([&] { ReadDepthMap(tmp.path() / "d.tiff"); }, {"d.tiff", "unsupported"});
}

// The PFM header's tokens (magic, width, height, scale) and an EXR
// attribute's name were quoted raw in errors: binary bytes and any length.
// Now the error names the file and the field and quotes at most a short
// printable token.
TEST(DepthMapIoBadInput, ErrorsDoNotEchoBinaryOrHugeTokens) {
  TempDir tmp;
  const fs::path pfm = tmp.path() / "t.pfm";
  const std::string huge = "SECRET" + std::string(10000, 'x');
  using testing::ExpectInputErrorWithoutEcho;
  auto expect = [&](const std::string& bytes, const std::vector<std::string>& needles) {
    std::ofstream(pfm, std::ios::binary) << bytes;
    ExpectInputErrorWithoutEcho([&] { ReadPfm(pfm); }, needles, {"SECRET", "xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx"});
  };
  expect(huge + "\n8 9\n-1\n", {"t.pfm", "magic", "not a PFM file", "a text of 10006 bytes"});
  expect("\x89PNG\x1a\x01\x02\n8 9\n-1\n", {"t.pfm", "magic", "'?PNG???'"});
  expect("Pf\n" + huge + " 9\n-1\n", {"t.pfm", "width", "invalid value"});
  expect("Pf\n8 \x1b[31m\x7f\n-1\n", {"t.pfm", "height", "invalid value '?[31m?'"});
  expect("Pf\n8 9\n" + huge + "\n", {"t.pfm", "scale", "invalid value"});
  // An EXR attribute name of 200 bytes (up to 255 with long names) with control bytes, its value truncated.
  const fs::path exr = tmp.path() / "t.exr";
  std::string bytes("\x76\x2f\x31\x01\x02\x04\x00\x00", 8);  // magic, version 2 with long names
  bytes += "SECRET\n" + std::string(193, 'x') + '\0' + "box2i" + '\0' + std::string("\xff\xff\x00\x00", 4);
  std::ofstream(exr, std::ios::binary) << bytes;
  ExpectInputErrorWithoutEcho([&] { ReadExrHeader(exr); }, {"t.exr", "a text of 200 bytes", "truncated"},
                              {"SECRET", "xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx"});
}

// A minimal OpenEXR header: magic, version 2, a one-channel chlist, a data
// window, the end of the header (no pixel data).
std::string ExrHeaderBytes(std::int32_t x1, std::int32_t y1, std::uint32_t version = 2) {
  std::string b;
  auto u32 = [&](std::uint32_t v) {
    for (int i = 0; i < 4; ++i) b.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
  };
  auto attr = [&](const std::string& name, const std::string& type, const std::string& value) {
    b += name + '\0' + type + '\0';
    u32(static_cast<std::uint32_t>(value.size()));
    b += value;
  };
  u32(20000630u);
  u32(version);
  std::string ch = std::string("Y") + '\0';
  for (std::uint32_t v : {2u, 0u, 1u, 1u})  // FLOAT, pLinear + reserved, xSampling, ySampling
    for (int i = 0; i < 4; ++i) ch.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
  ch.push_back('\0');
  attr("channels", "chlist", ch);
  std::string box;
  for (std::int32_t v : {0, 0, x1, y1})
    for (int i = 0; i < 4; ++i) box.push_back(static_cast<char>((static_cast<std::uint32_t>(v) >> (8 * i)) & 0xff));
  attr("dataWindow", "box2i", box);
  b.push_back('\0');
  return b;
}

TEST(DepthMapIo, ExrHeaderIsCheckedBeforeDecoding) {
  TempDir tmp;
  const cv::Mat depth(6, 7, CV_32F, cv::Scalar(1.5));
  WriteExr(tmp.path() / "d.exr", depth);
  const ExrHeader h = ReadExrHeader(tmp.path() / "d.exr");
  EXPECT_EQ(h.width, 7);
  EXPECT_EQ(h.height, 6);
  EXPECT_EQ(h.channels, 1);
  const fs::path exr = tmp.path() / "h.exr";
  std::ofstream(exr, std::ios::binary) << ExrHeaderBytes(99, 49);
  const ExrHeader small = ReadExrHeader(exr);
  EXPECT_EQ(small.width, 100);
  EXPECT_EQ(small.height, 50);
  // A header that claims 100000 x 100000 pixels (40 GB as floats): refused before any decoding.
  std::ofstream(exr, std::ios::binary) << ExrHeaderBytes(99999, 99999);
  ExpectInputError([&] { ReadExrHeader(exr); }, {"h.exr", "dataWindow", "100000x100000"});
  ExpectInputError([&] { ReadExr(exr); }, {"h.exr", "dataWindow"});
  std::ofstream(exr, std::ios::binary) << ExrHeaderBytes(-5, 10);  // x1 < x0
  ExpectInputError([&] { ReadExrHeader(exr); }, {"h.exr", "dataWindow"});
  std::ofstream(exr, std::ios::binary) << ExrHeaderBytes(10, 10, 2 | 0x1000);
  ExpectInputError([&] { ReadExrHeader(exr); }, {"h.exr", "multi-part"});
  const std::string full = ExrHeaderBytes(10, 10);
  for (std::size_t cut : {std::size_t(3), std::size_t(9), std::size_t(30), full.size() - 1}) {
    std::ofstream(exr, std::ios::binary) << full.substr(0, cut);
    SCOPED_TRACE(cut);
    ExpectInputError([&] { ReadExrHeader(exr); }, {"h.exr"});
  }
}

}  // namespace
}  // namespace lfrecon
