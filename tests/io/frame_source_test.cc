#include "io/frame_source.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <fstream>
#include <functional>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "util/error.h"
#include "common/test_util.h"

namespace lfrecon {
namespace {

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

}  // namespace
}  // namespace lfrecon
