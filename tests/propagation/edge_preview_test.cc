#include "propagation/edge_preview.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <opencv2/imgcodecs.hpp>

#include "propagation/bidirectional_photoconsistency.h"
#include "util/error.h"

namespace lfrecon {
namespace {

TEST(EdgePreview, DrawsSilhouetteAndTextureEdgesInTwoColours) {
  const cv::Mat frame(120, 200, CV_32FC3, cv::Scalar(0.2, 0.6, 0.4));
  cv::Mat classes = cv::Mat::zeros(120, 200, CV_8U);
  classes.at<std::uint8_t>(100, 50) = static_cast<std::uint8_t>(EdgeClass::kSilhouette);
  classes.at<std::uint8_t>(100, 60) = static_cast<std::uint8_t>(EdgeClass::kTexture);
  classes.at<std::uint8_t>(100, 70) = static_cast<std::uint8_t>(EdgeClass::kUnresolved);
  const cv::Mat out = RenderEdgePreview(frame, classes);
  ASSERT_EQ(out.type(), CV_8UC3);
  ASSERT_EQ(out.size(), frame.size());
  const cv::Vec3b sil = out.at<cv::Vec3b>(100, 50), tex = out.at<cv::Vec3b>(100, 60);
  EXPECT_EQ(sil, cv::Vec3b(kSilhouetteColor[0], kSilhouetteColor[1], kSilhouetteColor[2]));
  EXPECT_EQ(tex, cv::Vec3b(kTextureColor[0], kTextureColor[1], kTextureColor[2]));
  EXPECT_NE(sil, tex);
  // Elsewhere the frame is grey (all channels equal), unresolved pixels included.
  const cv::Vec3b bg = out.at<cv::Vec3b>(100, 70), other = out.at<cv::Vec3b>(60, 150);
  EXPECT_EQ(bg[0], bg[1]);
  EXPECT_EQ(bg[1], bg[2]);
  EXPECT_EQ(other, bg);
}

TEST(EdgePreview, WritesAPng) {
  const auto path = std::filesystem::temp_directory_path() / "lfrecon_edge_preview_test.png";
  std::filesystem::remove(path);
  cv::Mat frame(90, 160, CV_8UC3, cv::Scalar(10, 200, 90));
  WriteEdgePreview(path, frame, cv::Mat::zeros(90, 160, CV_8U));
  const cv::Mat back = cv::imread(path.string());
  EXPECT_EQ(back.size(), frame.size());
  std::filesystem::remove(path);
  EXPECT_THROW(WriteEdgePreview("/nonexistent-dir/x.png", frame, cv::Mat()), InputError);
}

}  // namespace
}  // namespace lfrecon
