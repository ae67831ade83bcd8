#include "synth/degradation.h"

#include <gtest/gtest.h>

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "synth/sequence.h"
#include "util/error.h"

namespace lfrecon::synth {
namespace {

double RotationDeg(const Rigid3d& a, const Rigid3d& b) {
  return Eigen::AngleAxisd(a.rotation * b.rotation.inverse()).angle() * 180.0 / M_PI;
}

TEST(Degradation, PoseErrorHasTheRequestedRmsAndIsDeterministic) {
  DegradationOptions d;
  d.pose_rotation_deg = 0.02;
  d.pose_translation_mm = 0.5;
  const Rigid3d truth = LookAt(Eigen::Vector3d(0.9, 0.1, 0.8), Eigen::Vector3d::Zero(), Eigen::Vector3d::UnitZ());
  double rot2 = 0, trans2 = 0;
  const int n = 4000;
  for (int i = 0; i < n; ++i) {
    const Rigid3d p = PerturbPose(truth, d, 7, i);
    rot2 += std::pow(RotationDeg(p, truth), 2);
    trans2 += (CameraCenter(p) - CameraCenter(truth)).squaredNorm();
  }
  EXPECT_NEAR(std::sqrt(rot2 / n), 0.02, 0.001);
  EXPECT_NEAR(std::sqrt(trans2 / n) * 1e3, 0.5, 0.025);
  const Rigid3d a = PerturbPose(truth, d, 7, 3), b = PerturbPose(truth, d, 7, 3), c = PerturbPose(truth, d, 8, 3);
  EXPECT_EQ((a.translation - b.translation).norm(), 0.0);
  EXPECT_GT((a.translation - c.translation).norm(), 0.0);
  // No error requested: the pose itself.
  EXPECT_EQ((PerturbPose(truth, DegradationOptions{}, 7, 3).translation - truth.translation).norm(), 0.0);
}

TEST(Degradation, ExposureGainIsASinusoidOfTheRequestedAmplitude) {
  DegradationOptions d;
  d.exposure_drift = 0.04;
  EXPECT_DOUBLE_EQ(ExposureGain(d, 0, 100), 1.0);
  EXPECT_NEAR(ExposureGain(d, 25, 100), 1.04, 1e-12);
  EXPECT_NEAR(ExposureGain(d, 75, 100), 0.96, 1e-12);
}

TEST(Degradation, OptionsAreChecked) {
  DegradationOptions d;
  d.exposure_drift = -0.1;
  EXPECT_THROW(d.Check(), OptionError);
  d = DegradationOptions{};
  d.motion_blur = 1.5;
  EXPECT_THROW(d.Check(), OptionError);
  d = DegradationOptions{};
  d.pose_rotation_deg = std::nan("");
  EXPECT_THROW(d.Check(), OptionError);
}

SynthOptions Small() {
  SynthOptions o;
  o.scene = "sphere";
  o.frames = 40;
  o.width = 96;
  o.height = 64;
  o.render.noise_sigma = 0;
  return o;
}

TEST(Degradation, SequenceRendersFromTrueAndGivesPerturbedPoses) {
  SynthOptions o = Small();
  o.degradation.pose_rotation_deg = 0.05;
  o.degradation.pose_translation_mm = 1.0;
  const SynthSequence noisy = SynthSequence::Create(o);
  const SynthSequence clean = SynthSequence::Create(Small());
  for (int i : {0, 17}) {
    EXPECT_EQ((noisy.cam_from_world(i).translation - clean.cam_from_world(i).translation).norm(), 0.0);
    const double dc = (CameraCenter(noisy.given_cam_from_world(i)) - CameraCenter(clean.cam_from_world(i))).norm();
    EXPECT_GT(dc, 0.0);
    EXPECT_LT(dc, 0.005);
    EXPECT_EQ(cv::norm(noisy.RenderImage(i), clean.RenderImage(i), cv::NORM_INF), 0.0);
  }
}

TEST(Degradation, ExposureScalesTheFrame) {
  SynthOptions o = Small();
  o.degradation.exposure_drift = 0.04;
  const SynthSequence drift = SynthSequence::Create(o);
  const SynthSequence clean = SynthSequence::Create(Small());
  const int i = 10;  // a quarter period: gain 1.04
  const cv::Mat a = drift.RenderImage(i), b = clean.RenderImage(i);
  cv::Mat expected;
  cv::min(b * 1.04, 1.0, expected);
  EXPECT_LT(cv::norm(a, expected, cv::NORM_INF), 1e-5);
  EXPECT_GT(cv::norm(a, b, cv::NORM_INF), 0.01);
}

TEST(Degradation, MotionBlurSmearsButKeepsTheMeanAndDepth) {
  SynthOptions o = Small();
  o.degradation.motion_blur = 1.0;
  const SynthSequence blur = SynthSequence::Create(o);
  const SynthSequence sharp = SynthSequence::Create(Small());
  const RenderResult a = blur.Render(5), b = sharp.Render(5);
  // Depth and labels are the frame's own pose's.
  EXPECT_EQ(cv::norm(a.depth, b.depth, cv::NORM_INF), 0.0);
  // Blur lowers the image's gradient energy but hardly changes its mean colour.
  cv::Mat ga, gb, grey_a, grey_b;
  cv::cvtColor(a.image, grey_a, cv::COLOR_BGR2GRAY);
  cv::cvtColor(b.image, grey_b, cv::COLOR_BGR2GRAY);
  cv::Sobel(grey_a, ga, CV_32F, 1, 0);
  cv::Sobel(grey_b, gb, CV_32F, 1, 0);
  EXPECT_LT(cv::norm(ga), 0.95 * cv::norm(gb));
  EXPECT_NEAR(cv::mean(a.image)[1], cv::mean(b.image)[1], 0.01);
}

}  // namespace
}  // namespace lfrecon::synth
