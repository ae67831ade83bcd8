#include "depth/depth_map.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

namespace lfrecon {
namespace {

bool SameBits(const cv::Mat& a, const cv::Mat& b) {
  if (a.empty() || b.empty()) return a.empty() && b.empty();
  if (a.size() != b.size() || a.type() != b.type()) return false;
  for (int r = 0; r < a.rows; ++r)
    if (std::memcmp(a.ptr(r), b.ptr(r), a.cols * a.elemSize()) != 0) return false;
  return true;
}

TEST(PackedDepthMap, UnpackGivesBackTheMapBitForBit) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.f, 1.f);
  DepthMap m(90, 160);
  for (int r = 0; r < m.depth.rows; ++r)
    for (int c = 0; c < m.depth.cols; ++c) {
      if (u(rng) > 0.2f) continue;  // ~20 % set, as a sparse map
      m.depth.at<float>(r, c) = 0.5f + u(rng);
      m.confidence.at<float>(r, c) = u(rng);
      m.label.at<std::uint8_t>(r, c) = 1 + (u(rng) > 0.5f);
    }
  // Odd pixels: a confidence or label without depth, -0.0, NaN.
  m.confidence.at<float>(0, 0) = 0.25f;
  m.label.at<std::uint8_t>(0, 1) = 2;
  m.depth.at<float>(0, 2) = -0.0f;
  m.depth.at<float>(0, 3) = std::nanf("");
  const PackedDepthMap p = PackedDepthMap::Pack(m);
  const DepthMap back = p.Unpack();
  EXPECT_TRUE(SameBits(m.depth, back.depth));
  EXPECT_TRUE(SameBits(m.confidence, back.confidence));
  EXPECT_TRUE(SameBits(m.label, back.label));
  EXPECT_GT(p.Count(), 90 * 160 / 10);
  EXPECT_LT(p.Count(), 90 * 160 * 3 / 10);
  // 13 bytes per set pixel against 9 per pixel of the map.
  EXPECT_LT(p.Bytes(), static_cast<std::size_t>(90 * 160 * 9 / 2));
}

TEST(PackedDepthMap, EmptyPartsStayEmpty) {
  DepthMap m;
  m.depth = cv::Mat::zeros(4, 5, CV_32F);
  m.depth.at<float>(1, 2) = 2.0f;
  const DepthMap back = PackedDepthMap::Pack(m).Unpack();
  EXPECT_TRUE(back.confidence.empty());
  EXPECT_TRUE(back.label.empty());
  EXPECT_TRUE(SameBits(m.depth, back.depth));
  EXPECT_TRUE(PackedDepthMap::Pack(DepthMap()).Unpack().depth.empty());
}

}  // namespace
}  // namespace lfrecon
