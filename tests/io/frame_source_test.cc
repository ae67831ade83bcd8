#include "io/frame_source.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <functional>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "io/depth_map_io.h"
#include "io/image_header.h"
#include "util/error.h"
#include "common/black_png.h"
#include "common/test_util.h"

namespace lfrecon {
namespace {

using testing::BlackPng;
using testing::TempDir;
using testing::ExpectInputError;
namespace fs = std::filesystem;

// An 8-bit BGR image whose pixels encode (frame, row, column).
cv::Mat Pattern(int frame, int rows = 12, int cols = 16) {
  cv::Mat m(rows, cols, CV_8UC3);
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) m.at<cv::Vec3b>(r, c) = cv::Vec3b(10 * frame, 7 * r, 5 * c + 1);
  return m;
}

TEST(FrameSource, NaturalNameOrder) {
  EXPECT_TRUE(NaturalNameLess("f2.png", "f10.png"));
  EXPECT_FALSE(NaturalNameLess("f10.png", "f2.png"));
  EXPECT_TRUE(NaturalNameLess("00009.jpg", "00010.jpg"));
  EXPECT_TRUE(NaturalNameLess("a.png", "b.png"));
  EXPECT_TRUE(NaturalNameLess("a", "a1"));
  EXPECT_FALSE(NaturalNameLess("x", "x"));
  EXPECT_NE(NaturalNameLess("01", "1"), NaturalNameLess("1", "01"));  // strict
}

TEST(FrameSource, ToFloatBgrConversions) {
  cv::Mat gray8(2, 3, CV_8U, cv::Scalar(51));
  cv::Mat f = ToFloatBgr(gray8);
  ASSERT_EQ(f.type(), CV_32FC3);
  EXPECT_FLOAT_EQ(f.at<cv::Vec3f>(1, 2)[1], 0.2f);
  cv::Mat bgr16(2, 3, CV_16UC3, cv::Scalar(0, 65535, 13107));
  f = ToFloatBgr(bgr16);
  EXPECT_FLOAT_EQ(f.at<cv::Vec3f>(0, 0)[1], 1.0f);
  EXPECT_FLOAT_EQ(f.at<cv::Vec3f>(0, 0)[2], 0.2f);
  cv::Mat bgra(2, 3, CV_8UC4, cv::Scalar(255, 0, 0, 7));
  f = ToFloatBgr(bgra);
  ASSERT_EQ(f.type(), CV_32FC3);
  EXPECT_EQ(f.at<cv::Vec3f>(0, 0), cv::Vec3f(1, 0, 0));
}

TEST(FrameSource, ImageFolderReadsLazilyInNameOrder) {
  TempDir tmp;
  for (int i : {10, 2, 1})
    cv::imwrite((tmp.path() / ("f" + std::to_string(i) + ".png")).string(), Pattern(i));
  std::ofstream(tmp.path() / "notes.txt") << "not an image";
  auto source = ImageFolderSource::FromFolder(tmp.path());
  ASSERT_EQ(source->NumFrames(), 3);
  EXPECT_EQ(source->names(), (std::vector<std::string>{"f1.png", "f2.png", "f10.png"}));
  Frame frame;
  std::vector<int> seen;
  while (source->Next(&frame)) {
    ASSERT_EQ(frame.image.type(), CV_32FC3);
    const int id = std::stoi(frame.name.substr(1));
    EXPECT_FLOAT_EQ(frame.image.at<cv::Vec3f>(3, 4)[0], 10 * id / 255.f);
    EXPECT_FLOAT_EQ(frame.image.at<cv::Vec3f>(3, 4)[1], 21 / 255.f);
    EXPECT_FLOAT_EQ(frame.image.at<cv::Vec3f>(3, 4)[2], 21 / 255.f);
    seen.push_back(frame.index);
  }
  EXPECT_EQ(seen, (std::vector<int>{0, 1, 2}));
  const Frame second = source->Read(1);
  EXPECT_EQ(second.name, "f2.png");
  EXPECT_THROW(source->Read(3), InputError);

  // Lazy: a file removed after the listing is noticed only when its turn comes.
  auto again = ImageFolderSource::FromFolder(tmp.path());
  fs::remove(tmp.path() / "f10.png");
  EXPECT_TRUE(again->Next(&frame));
  EXPECT_TRUE(again->Next(&frame));
  ExpectInputError([&] { again->Next(&frame); }, {"f10.png"});
}

TEST(FrameSource, UnreadableFramesNameTheFile) {
  TempDir tmp;
  cv::imwrite((tmp.path() / "a.png").string(), Pattern(0));
  std::ofstream(tmp.path() / "b.jpg", std::ios::binary) << "\xff\xd8 garbage, not really a JPEG \x01\x02\x03";
  std::ofstream(tmp.path() / "c.png", std::ios::binary) << "";
  ImageFolderSource source(tmp.path(), {"a.png", "b.jpg", "c.png", "missing.png"});
  Frame frame;
  ASSERT_TRUE(source.Next(&frame));
  ExpectInputError([&] { source.Next(&frame); }, {"b.jpg"});
  ExpectInputError([&] { source.Read(2); }, {"c.png"});
  ExpectInputError([&] { source.Read(3); }, {"missing.png", "does not exist"});
  ExpectInputError([&] { ImageFolderSource::FromFolder(tmp.path() / "nope"); }, {"nope", "does not exist"});
  ExpectInputError([&] { ReadImageFloat(tmp.path() / "b.jpg"); }, {"b.jpg"});
}

TEST(FrameSource, WriteImageFloatRoundTrip) {
  TempDir tmp;
  cv::Mat f;
  Pattern(3).convertTo(f, CV_32FC3, 1 / 255.0);
  WriteImageFloat(tmp.path() / "x.png", f);
  const cv::Mat back = ReadImageFloat(tmp.path() / "x.png");
  EXPECT_LT(cv::norm(back, f, cv::NORM_INF), 1e-6);
  ExpectInputError([&] { WriteImageFloat(tmp.path() / "no_such_dir" / "x.png", f); }, {"x.png"});
}

TEST(FrameSource, VideoSequentialAndSeek) {
  TempDir tmp;
  const fs::path video = tmp.path() / "v.avi";
  const int n = 12;
  {
    cv::VideoWriter writer(video.string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0,
                           cv::Size(64, 48));
    if (!writer.isOpened()) GTEST_SKIP() << "OpenCV cannot write MJPG video here";
    // Flat colours per frame survive JPEG compression to within a few levels.
    for (int i = 0; i < n; ++i) writer.write(cv::Mat(48, 64, CV_8UC3, cv::Scalar(20 * i, 100, 200 - 10 * i)));
  }
  VideoSource source(video);
  EXPECT_EQ(source.NumFrames(), n);
  Frame frame;
  int count = 0;
  while (source.Next(&frame)) {
    EXPECT_EQ(frame.index, count);
    EXPECT_EQ(frame.image.type(), CV_32FC3);
    EXPECT_EQ(frame.image.size(), cv::Size(64, 48));
    EXPECT_NEAR(frame.image.at<cv::Vec3f>(20, 30)[0], 20 * count / 255.0, 4 / 255.0);
    ++count;
  }
  EXPECT_EQ(count, n);
  EXPECT_EQ(frame.name, "frame_00011");
  for (int i : {7, 2, 3, 11}) {
    const Frame f = source.Read(i);
    EXPECT_EQ(f.index, i);
    EXPECT_NEAR(f.image.at<cv::Vec3f>(20, 30)[0], 20 * i / 255.0, 4 / 255.0) << i;
  }
  ExpectInputError([&] { source.Read(n); }, {"v.avi", "out of range"});

  ExpectInputError([&] { VideoSource s(tmp.path() / "none.mp4"); }, {"none.mp4", "does not exist"});
  std::ofstream(tmp.path() / "junk.mp4", std::ios::binary) << std::string(1000, 'x');
  ExpectInputError([&] { VideoSource s(tmp.path() / "junk.mp4"); }, {"junk.mp4"});
}

// ---- image headers, checked before decoding ---------------------------------

std::string FileBytes(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

// Peak RSS (VmHWM) in bytes since the last ResetPeakRss(); -1 where Linux cannot reset it.
bool ResetPeakRss() { return static_cast<bool>(std::ofstream("/proc/self/clear_refs") << "5"); }
long PeakRssBytes() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::stol(line.substr(6)) * 1024;
  return -1;
}

TEST(ImageHeader, PngAndJpegSizesWithoutDecoding) {
  TempDir tmp;
  const cv::Mat image = Pattern(3, 37, 53);
  cv::imwrite((tmp.path() / "a.png").string(), image);
  cv::imwrite((tmp.path() / "a.jpg").string(), image);
  cv::imwrite((tmp.path() / "p.jpg").string(), image, {cv::IMWRITE_JPEG_PROGRESSIVE, 1});
  for (const char* name : {"a.png", "a.jpg", "p.jpg"}) {
    SCOPED_TRACE(name);
    const auto h = ReadImageHeader(FileBytes(tmp.path() / name));
    ASSERT_TRUE(h.has_value());
    EXPECT_EQ(h->width, 53);
    EXPECT_EQ(h->height, 37);
    EXPECT_TRUE(h->complete);
    EXPECT_EQ(ReadImageFloat(tmp.path() / name, cv::Size(53, 37)).size(), cv::Size(53, 37));
  }
  EXPECT_EQ(ReadImageHeader(BlackPng(20000, 20000))->width, 20000);
  EXPECT_FALSE(ReadImageHeader("BM not a png or jpeg").has_value());
  EXPECT_FALSE(ReadImageHeader("").has_value());
}

// A JPEG cut in half decodes "successfully" (libjpeg warns and fills grey): refused, naming the file.
TEST(ImageHeader, TruncatedJpegIsAnErrorNamingTheFile) {
  TempDir tmp;
  const fs::path full = tmp.path() / "full.jpg", half = tmp.path() / "half.jpg";
  for (bool progressive : {false, true}) {
    SCOPED_TRACE(progressive);
    cv::Mat noise(120, 160, CV_8UC3);
    cv::randu(noise, 0, 255);  // no long runs: the entropy-coded data fills most of the file
    cv::imwrite(full.string(), noise, {cv::IMWRITE_JPEG_PROGRESSIVE, progressive ? 1 : 0});
    const std::string bytes = FileBytes(full);
    std::ofstream(half, std::ios::binary) << bytes.substr(0, bytes.size() / 2);
    EXPECT_FALSE(ReadImageHeader(bytes.substr(0, bytes.size() / 2))->complete);
    ExpectInputError([&] { ReadImageFloat(half); }, {"half.jpg", "truncated"});
    ImageFolderSource source(tmp.path(), {"full.jpg", "half.jpg"});
    Frame frame;
    ASSERT_TRUE(source.Next(&frame));
    ExpectInputError([&] { source.Next(&frame); }, {"half.jpg", "truncated"});
    // All but the last byte (EOI's 0xD9): still truncated. Data after EOI is allowed.
    std::ofstream(half, std::ios::binary) << bytes.substr(0, bytes.size() - 1);
    ExpectInputError([&] { ReadImageFloat(half); }, {"half.jpg", "truncated"});
    std::ofstream(half, std::ios::binary) << bytes << "trailing bytes after EOI";
    EXPECT_EQ(ReadImageFloat(half).size(), cv::Size(160, 120));
  }
}

// A 4000x4000 frame among 64x48 ones is refused from its header, before any
// pixel is decoded (decoding it took ~260 MB: 16 MB grey, 192 MB float BGR).
TEST(ImageHeader, FrameLargerThanItsCameraIsRefusedBeforeDecoding) {
  TempDir tmp;
  cv::imwrite((tmp.path() / "a.png").string(), Pattern(0, 48, 64));
  std::ofstream(tmp.path() / "big.png", std::ios::binary) << BlackPng(4000, 4000);
  ImageFolderSource source(tmp.path(), {"a.png", "big.png"});
  source.ExpectSizes({cv::Size(64, 48), cv::Size(64, 48)});
  Frame frame;
  ASSERT_TRUE(source.Next(&frame));
  const bool measured = ResetPeakRss();
  const long before = PeakRssBytes();
  ExpectInputError([&] { source.Next(&frame); }, {"big.png", "4000x4000", "64x48"});
  if (measured && before > 0) {
    const long grew = PeakRssBytes() - before;
    std::printf("peak RSS grew by %.1f MB while refusing the 4000x4000 frame\n", grew / 1e6);
    EXPECT_LT(grew, 8l << 20);
  }
  // Without a camera to compare with, the pixel cap still holds (the IDAT need not even be valid).
  std::string huge = BlackPng(20000, 20000);
  std::ofstream(tmp.path() / "huge.png", std::ios::binary) << huge;
  ExpectInputError([&] { ReadImageFloat(tmp.path() / "huge.png"); }, {"huge.png", "20000x20000", "pixels"});
  // Under the cap and without a camera it is decoded, and the measure sees that.
  const bool remeasured = ResetPeakRss();
  const long before_decode = PeakRssBytes();
  EXPECT_EQ(ReadImageFloat(tmp.path() / "big.png").size(), cv::Size(4000, 4000));
  if (remeasured && before_decode > 0) EXPECT_GT(PeakRssBytes() - before_decode, 100l << 20);
}


// Little-endian bytes of `v` into `b` at `at`.
void PutLe(std::string& b, std::size_t at, std::uint32_t v, int n) {
  for (int i = 0; i < n; ++i) b[at + i] = static_cast<char>((v >> (8 * i)) & 0xff);
}

// A BMP whose header says width x height (24-bit, uncompressed) followed by a
// few bytes of pixels: a small file with a huge (lying) header.
std::string BmpWithHeader(std::uint32_t width, std::uint32_t height) {
  std::string b(54, '\0');
  b[0] = 'B';
  b[1] = 'M';
  PutLe(b, 2, 54 + 64, 4);  // file size
  PutLe(b, 10, 54, 4);      // pixel data offset
  PutLe(b, 14, 40, 4);      // BITMAPINFOHEADER
  PutLe(b, 18, width, 4);
  PutLe(b, 22, height, 4);
  PutLe(b, 26, 1, 2);   // planes
  PutLe(b, 28, 24, 2);  // bits per pixel
  return b + std::string(64, '\x7f');
}

// A little-endian baseline TIFF (8-bit grey, one uncompressed strip) whose
// directory says width x height, with `data` bytes of pixels.
std::string TiffWithHeader(std::uint32_t width, std::uint32_t height, std::size_t data) {
  const std::uint16_t entries = 9;
  const std::size_t ifd = 8, pixels = ifd + 2 + 12 * entries + 4;
  std::string b(pixels, '\0');
  b[0] = b[1] = 'I';
  PutLe(b, 2, 42, 2);
  PutLe(b, 4, ifd, 4);
  PutLe(b, ifd, entries, 2);
  const std::uint32_t tags[entries][3] = {  // tag, type (3 SHORT, 4 LONG), value
      {256, 4, width}, {257, 4, height}, {258, 3, 8},  {259, 3, 1},
      {262, 3, 1},     {273, 4, static_cast<std::uint32_t>(pixels)},
      {277, 3, 1},     {278, 4, height}, {279, 4, static_cast<std::uint32_t>(data)}};
  for (int i = 0; i < entries; ++i) {
    const std::size_t e = ifd + 2 + 12 * i;
    PutLe(b, e, tags[i][0], 2);
    PutLe(b, e + 2, tags[i][1], 2);
    PutLe(b, e + 4, 1, 4);
    PutLe(b, e + 8, tags[i][2], tags[i][1] == 3 ? 2 : 4);
  }
  return b + std::string(data, '\x40');
}

// Every format imread decodes has its size read from its header and checked
// before any pixel is decoded (formerly only PNG and JPEG: a 20000x20000 TIFF
// or BMP was decoded first, 1.2 GB for this BMP). Sizes of real files of each
// format this OpenCV writes; lying huge headers refused naming the file,
// without the memory; a format whose header cannot be read refused.
TEST(ImageHeader, EveryFormatsSizeIsCheckedBeforeDecoding) {
  TempDir tmp;
  const cv::Mat image = Pattern(3, 37, 53);
  cv::Mat grey, floats;
  cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  image.convertTo(floats, CV_32FC3, 1.0 / 255);
  struct Case {
    const char* name;
    const cv::Mat* mat;
    const char* format;
  };
  const Case cases[] = {{"a.bmp", &image, "bmp"},  {"a.tif", &image, "tiff"}, {"a.webp", &image, "webp"},
                        {"a.ppm", &image, "pnm"},  {"a.pgm", &grey, "pnm"},   {"a.pam", &image, "pam"},
                        {"a.pfm", &floats, "pfm"}, {"a.hdr", &floats, "hdr"}, {"a.ras", &image, "sunras"}};
  int checked = 0;
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const fs::path p = tmp.path() / c.name;
    bool written = false;
    try {
      written = cv::imwrite(p.string(), *c.mat);
    } catch (const cv::Exception&) {
    }
    if (!written) {
      std::printf("%s: this OpenCV cannot write it, not checked\n", c.name);
      continue;
    }
    const auto h = ReadOtherImageHeader(FileBytes(p));
    ASSERT_TRUE(h.has_value());
    EXPECT_EQ(h->format, c.format);
    EXPECT_EQ(h->width, 53);
    EXPECT_EQ(h->height, 37);
    EXPECT_EQ(ReadImageFloat(p, cv::Size(53, 37)).size(), cv::Size(53, 37));
    ExpectInputError([&] { ReadImageFloat(p, cv::Size(64, 48)); }, {c.name, "image header is 53x37", "64x48"});
    ++checked;
  }
  EXPECT_GE(checked, 7);  // Debian's OpenCV writes all of them
  {  // OpenEXR: through ReadExrHeader
    const fs::path p = tmp.path() / "a.exr";
    WriteExr(p, cv::Mat(37, 53, CV_32F, cv::Scalar(0.5)));
    EXPECT_EQ(ReadImageFloat(p, cv::Size(53, 37)).size(), cv::Size(53, 37));
    ExpectInputError([&] { ReadImageFloat(p, cv::Size(64, 48)); }, {"a.exr", "53x37", "64x48"});
  }
  // Small files whose headers say 20000x20000: refused from the header, before
  // OpenCV allocates (and fills) the 1.2 GB the BMP would take.
  std::ofstream(tmp.path() / "huge.bmp", std::ios::binary) << BmpWithHeader(20000, 20000);
  std::ofstream(tmp.path() / "huge.tif", std::ios::binary) << TiffWithHeader(20000, 20000, 64);
  EXPECT_EQ(ReadOtherImageHeader(TiffWithHeader(20000, 20000, 64))->width, 20000);
  const bool measured = ResetPeakRss();
  const long before = PeakRssBytes();
  for (const char* name : {"huge.bmp", "huge.tif"}) {
    SCOPED_TRACE(name);
    ExpectInputError([&] { ReadImageFloat(tmp.path() / name); }, {name, "20000x20000", "pixels"});
    ExpectInputError([&] { ReadImageFloat(tmp.path() / name, cv::Size(64, 48)); }, {name, "20000x20000", "64x48"});
  }
  if (measured && before > 0) {
    const long grew = PeakRssBytes() - before;
    std::printf("peak RSS grew by %.1f MB while refusing the 20000x20000 BMP and TIFF\n", grew / 1e6);
    EXPECT_LT(grew, 8l << 20);
  }
  // A frame source checks them against the cameras the same way.
  cv::imwrite((tmp.path() / "ok.bmp").string(), Pattern(0, 48, 64));
  ImageFolderSource source(tmp.path(), {"ok.bmp", "huge.bmp"});
  source.ExpectSizes({cv::Size(64, 48), cv::Size(64, 48)});
  Frame frame;
  ASSERT_TRUE(source.Next(&frame));
  ExpectInputError([&] { source.Next(&frame); }, {"huge.bmp", "20000x20000", "64x48"});
  // The real small TIFF of that shape decodes (the built header is valid TIFF).
  std::ofstream(tmp.path() / "small.tif", std::ios::binary) << TiffWithHeader(16, 8, 16 * 8);
  EXPECT_EQ(ReadImageFloat(tmp.path() / "small.tif", cv::Size(16, 8)).size(), cv::Size(16, 8));
  // Formats whose size cannot be read are refused, naming the file.
  std::ofstream(tmp.path() / "x.gif", std::ios::binary) << "GIF89a\x10\x00\x08\x00" << std::string(32, '\0');
  ExpectInputError([&] { ReadImageFloat(tmp.path() / "x.gif"); }, {"x.gif", "unrecognised image format"});
  std::ofstream(tmp.path() / "cut.bmp", std::ios::binary) << BmpWithHeader(16, 8).substr(0, 16);
  ExpectInputError([&] { ReadImageFloat(tmp.path() / "cut.bmp"); }, {"cut.bmp", "bmp header gives no image size"});
}

}  // namespace
}  // namespace lfrecon
