#include "poses/pose_refinement.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>

#include "synth/sequence.h"
#include "util/error.h"

namespace lfrecon {
namespace {

double Rms(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return v.empty() ? 0 : std::sqrt(s / v.size());
}

struct PoseErrors {
  double rotation_deg = 0, center_mm = 0;                   // RMS per frame against the truth
  double relative_rotation_deg = 0, relative_center_mm = 0;  // RMS of frame pairs (k, k + gap)
};

PoseErrors Errors(const std::vector<PinholeView>& est, const std::vector<PinholeView>& truth, int gap) {
  std::vector<double> r, c, rr, rc;
  for (std::size_t i = 0; i < est.size(); ++i) {
    r.push_back(RotationDifferenceDeg(est[i], truth[i]));
    c.push_back(1e3 * (est[i].Center() - truth[i].Center()).norm());
    const std::size_t j = i + static_cast<std::size_t>(gap);
    if (j >= est.size()) continue;
    const Eigen::Matrix3d Re = est[j].R * est[i].R.transpose(), Rt = truth[j].R * truth[i].R.transpose();
    rr.push_back(Eigen::AngleAxisd(Re * Rt.transpose()).angle() * 180.0 / M_PI);
    rc.push_back(1e3 * (est[i].R * (est[j].Center() - est[i].Center()) -
                        truth[i].R * (truth[j].Center() - truth[i].Center()))
                           .norm());
  }
  return {Rms(r), Rms(c), Rms(rr), Rms(rc)};
}

synth::SynthSequence Sequence(double rot_deg, double trans_mm) {
  synth::SynthOptions o;
  o.scene = "tabletop";
  o.frames = 60;
  o.loops = 60 * 0.75 / 360.0;  // 0.75° apart, like the figurines
  o.width = 320;
  o.height = 180;
  o.render.quantize = true;
  o.degradation.pose_rotation_deg = rot_deg;
  o.degradation.pose_translation_mm = trans_mm;
  return synth::SynthSequence::Create(o);
}

std::vector<PinholeView> Views(const synth::SynthSequence& seq, bool given) {
  std::vector<PinholeView> v;
  for (int i = 0; i < seq.NumFrames(); ++i)
    v.emplace_back(seq.camera(), given ? seq.given_cam_from_world(i) : seq.cam_from_world(i));
  return v;
}

TEST(PoseRefinement, ReducesThePoseErrorOfAGeneratedLoop) {
  const synth::SynthSequence seq = Sequence(0.05, 1.0);
  const std::vector<PinholeView> truth = Views(seq, false), given = Views(seq, true);
  auto frames = seq.OpenFrames();
  const PoseRefinementResult r = RefinePoses(*frames, given, PoseRefinementOptions{});
  const PoseErrors before = Errors(given, truth, 1), after = Errors(r.views, truth, 1);
  std::printf("tracks %lld; RMS rotation %.4f -> %.4f deg, centre %.3f -> %.3f mm; neighbours: rotation %.4f -> "
              "%.4f deg, centre %.3f -> %.3f mm\n",
              static_cast<long long>(r.stats.tracks), before.rotation_deg, after.rotation_deg, before.center_mm,
              after.center_mm, before.relative_rotation_deg, after.relative_rotation_deg, before.relative_center_mm,
              after.relative_center_mm);
  EXPECT_GT(r.stats.tracks, 500);
  EXPECT_LT(r.stats.median_reprojection_after_px, r.stats.median_reprojection_before_px);
  // What neighbouring views' depth sees: at least halved.
  EXPECT_LT(after.relative_rotation_deg, 0.5 * before.relative_rotation_deg);
  EXPECT_LT(after.relative_center_mm, 0.5 * before.relative_center_mm);
  // And no worse against the truth as a whole.
  EXPECT_LT(after.rotation_deg, before.rotation_deg);
  EXPECT_LT(after.center_mm, before.center_mm);
}

TEST(PoseRefinement, LeavesExactPosesNearlyAlone) {
  const synth::SynthSequence seq = Sequence(0, 0);
  const std::vector<PinholeView> truth = Views(seq, false);
  auto frames = seq.OpenFrames();
  const PoseRefinementResult r = RefinePoses(*frames, truth, PoseRefinementOptions{});
  const PoseErrors after = Errors(r.views, truth, 1);
  std::printf("exact poses moved by RMS %.4f deg, %.3f mm; neighbours %.4f deg, %.3f mm\n", after.rotation_deg,
              after.center_mm, after.relative_rotation_deg, after.relative_center_mm);
  EXPECT_LT(after.rotation_deg, 0.02);
  EXPECT_LT(after.center_mm, 0.5);
}

TEST(PoseRefinement, TooFewFramesKeepTheGivenPoses) {
  const synth::SynthSequence seq = Sequence(0.05, 1.0);
  const std::vector<PinholeView> given = Views(seq, true);
  std::vector<PinholeView> two(given.begin(), given.begin() + 2);
  auto frames = seq.OpenFrames();
  const PoseRefinementResult r = RefinePoses(*frames, two, PoseRefinementOptions{});
  ASSERT_EQ(r.views.size(), 2u);
  EXPECT_EQ((r.views[1].t - two[1].t).norm(), 0.0);
}

TEST(PoseRefinement, OptionsAreChecked) {
  PoseRefinementOptions o;
  o.min_track_length = 1;
  EXPECT_THROW(o.Check(), OptionError);
  o = PoseRefinementOptions{};
  o.prior_rotation_deg = 0;
  EXPECT_THROW(o.Check(), OptionError);
}

}  // namespace
}  // namespace lfrecon
