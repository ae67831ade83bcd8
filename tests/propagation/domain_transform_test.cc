#include "propagation/domain_transform.h"

#include <gtest/gtest.h>

#include <opencv2/imgproc.hpp>
#include <opencv2/ximgproc/edge_filter.hpp>

#include "util/error.h"

namespace lfrecon {
namespace {

cv::Mat Guide() {
  // Smooth gradients, a sharp-edged disc and some noise.
  cv::Mat g(90, 140, CV_32FC3);
  for (int r = 0; r < g.rows; ++r)
    for (int c = 0; c < g.cols; ++c) g.at<cv::Vec3f>(r, c) = cv::Vec3f(c / 140.0f, r / 90.0f, 0.5f);
  cv::circle(g, cv::Point(70, 45), 25, cv::Scalar(0.9, 0.1, 0.2), cv::FILLED);
  cv::Mat noise(g.size(), CV_32FC3);
  cv::randn(noise, 0, 0.01);
  return g + noise;
}

TEST(DomainTransformFilter, MatchesOpenCvRecursiveFilter) {
  const cv::Mat guide = Guide();
  cv::Mat data(guide.size(), CV_32FC4);
  cv::randu(data, 0, 1);
  for (const double sigma_s : {5.0, 30.0})
    for (const double sigma_r : {0.1, 0.4}) {
      cv::Mat expected;
      cv::ximgproc::dtFilter(guide, data, expected, sigma_s, sigma_r, cv::ximgproc::DTF_RF, 3);
      cv::Mat ours = data.clone();
      DomainTransformFilter(guide, sigma_s, sigma_r, 3).Apply(ours);
      EXPECT_LT(cv::norm(ours, expected, cv::NORM_INF), 2e-4) << sigma_s << " " << sigma_r;
    }
}

TEST(DomainTransformFilter, AnyChannelCountFiltersEachChannelAlike) {
  const cv::Mat guide = Guide();
  cv::Mat one(guide.size(), CV_32F);
  cv::randu(one, 0, 1);
  cv::Mat one_filtered = one.clone();
  const DomainTransformFilter f(guide, 20, 0.3, 3);
  f.Apply(one_filtered);
  for (int n : {2, 7, 11}) {
    std::vector<cv::Mat> planes(n, one);
    cv::Mat many;
    cv::merge(planes, many);
    f.Apply(many);
    std::vector<cv::Mat> out;
    cv::split(many, out);
    for (const cv::Mat& p : out) EXPECT_LT(cv::norm(p, one_filtered, cv::NORM_INF), 1e-5) << n;
  }
}

TEST(DomainTransformFilter, StopsAtEdgesAndKeepsConstants) {
  // A step guide: values on the left must not reach the right.
  cv::Mat guide(40, 80, CV_32FC1, cv::Scalar(0.2f));
  guide.colRange(40, 80).setTo(0.9f);
  cv::Mat data(40, 80, CV_32FC2, cv::Scalar(0, 0));
  data.colRange(0, 40).setTo(cv::Scalar(1.0f, 1.0f));
  data.colRange(40, 80).setTo(cv::Scalar(0.0f, 1.0f));  // channel 1 constant
  DomainTransformFilter(guide, 30, 0.05, 3).Apply(data);
  double lo, hi;
  std::vector<cv::Mat> ch;
  cv::split(data, ch);
  cv::minMaxLoc(ch[0].colRange(42, 80), &lo, &hi);
  EXPECT_LT(hi, 1e-3);
  cv::minMaxLoc(ch[0].colRange(0, 38), &lo, &hi);
  EXPECT_GT(lo, 0.999);
  cv::minMaxLoc(ch[1], &lo, &hi);
  EXPECT_NEAR(lo, 1.0, 1e-5);
  EXPECT_NEAR(hi, 1.0, 1e-5);
}

TEST(DomainTransformFilter, RejectsBadInput) {
  EXPECT_THROW(DomainTransformFilter(cv::Mat(), 10, 0.1), OptionError);
  EXPECT_THROW(DomainTransformFilter(cv::Mat(10, 10, CV_8UC3), 10, 0.1), OptionError);
  EXPECT_THROW(DomainTransformFilter(cv::Mat(10, 10, CV_32FC3), 0, 0.1), OptionError);
  const DomainTransformFilter f(cv::Mat(10, 10, CV_32FC3, cv::Scalar(0.5, 0.5, 0.5)), 10, 0.1);
  cv::Mat wrong(5, 5, CV_32F);
  EXPECT_THROW(f.Apply(wrong), OptionError);
}

}  // namespace
}  // namespace lfrecon
