#include "propagation/bidirectional_photoconsistency.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "../depth/synth_views.h"
#include "geometry/rigid3.h"
#include "propagation/colour_difference.h"
#include "util/error.h"

namespace lfrecon {
namespace {

using testing::MakeSynthViews;
using testing::MakeCustomViews;
using testing::SynthViews;

constexpr std::uint8_t kSil = static_cast<std::uint8_t>(EdgeClass::kSilhouette);
constexpr std::uint8_t kTex = static_cast<std::uint8_t>(EdgeClass::kTexture);

// Three textured cards at 0.8-0.95 m, turned 10-25° about the vertical,
// in front of a textured wall at 1.9 m: occluding contours with no limbs.
synth::Scene CardsScene() {
  synth::Scene s("cards");
  s.set_foreground_bbox({Eigen::Vector3d(-0.2, -0.3, 0.05), Eigen::Vector3d(0.2, 0.3, 0.55)});
  const auto card = [&](const Eigen::Vector3d& c, double yaw_deg, double hu, double hv, const synth::Material& m) {
    const Eigen::Matrix3d R = Eigen::AngleAxisd(yaw_deg * M_PI / 180, Eigen::Vector3d::UnitZ()).toRotationMatrix();
    s.Add(synth::Primitive::Rect(c, R * Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ(), hu, hv, m).Foreground());
  };
  card({0.05, -0.12, 0.35}, 15, 0.07, 0.1, synth::Material::Noise({0.5f, 0.1f, 0.1f}, {1.0f, 0.8f, 0.5f}, 0.012));
  card({-0.05, 0.1, 0.25}, -20, 0.08, 0.06, synth::Material::Checker({0.1f, 0.2f, 0.5f}, {0.9f, 0.9f, 0.7f}, 0.02));
  card({0.1, 0.05, 0.42}, 25, 0.05, 0.05, synth::Material::Noise({0.1f, 0.4f, 0.1f}, {0.8f, 1.0f, 0.6f}, 0.01));
  s.Add(synth::Primitive::Rect({-1.0, 0, 0.3}, Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ(), 2.0, 1.5,
                               synth::Material::Noise({0.3f, 0.3f, 0.35f}, {0.85f, 0.8f, 0.7f}, 0.03)));
  s.Add(synth::Primitive::Sphere(Eigen::Vector3d::Zero(), 3.0,
                                 synth::Material::Noise({0.35f, 0.42f, 0.55f}, {0.8f, 0.82f, 0.86f}, 0.2)));
  return s;
}

// Ground-truth depth at the pixels the depth stage would estimate (‖∇I‖ > g), labelled from V.
DepthMap TruthAtEdges(const SynthViews& v, double g = 0.05) {
  const cv::Mat grad = GradientMagnitude(v.ref.image);
  DepthMap m(v.ref.image.rows, v.ref.image.cols);
  for (int r = 0; r < m.depth.rows; ++r)
    for (int c = 0; c < m.depth.cols; ++c) {
      const double t = v.truth.depth.at<double>(r, c);
      if (!(grad.at<float>(r, c) > g) || !(t > 0)) continue;
      m.depth.at<float>(r, c) = static_cast<float>(t);
      m.confidence.at<float>(r, c) = 1.0f;
      const bool fg = v.volume.Contains(v.ref.view.Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), t));
      m.label.at<std::uint8_t>(r, c) =
          static_cast<std::uint8_t>(fg ? DepthLabel::kForeground : DepthLabel::kBackground);
    }
  return m;
}

// Ground truth of the edge classes from the generator's depth. Along the
// pixel's gradient direction: a silhouette edge when the true depth jumps by
// more than 5 % within one pixel on either side (the pixel lies on an
// occluding contour); a texture edge when it stays within 1.5 % over 4 pixels
// on either side and no pixel within 2 px mixes primitives. Pixels in between
// (2-4 px from a contour, whose samples straddle it) are not scored.
struct EdgeTruth {
  cv::Mat silhouette, texture;  // CV_8U, 255 = yes
};

EdgeTruth ClassifyTruth(const SynthViews& v, const DepthMap& at) {
  const cv::Mat dir = GradientDirection(v.ref.image);
  EdgeTruth t{cv::Mat::zeros(at.depth.size(), CV_8U), cv::Mat::zeros(at.depth.size(), CV_8U)};
  const cv::Mat& d = v.truth.depth;
  for (int r = 0; r < d.rows; ++r)
    for (int c = 0; c < d.cols; ++c) {
      if (!(at.depth.at<float>(r, c) > 0)) continue;
      const cv::Vec2f n = dir.at<cv::Vec2f>(r, c);
      if (n[0] == 0 && n[1] == 0) continue;
      const double d0 = d.at<double>(r, c);
      double max_rel = 0, max_rel_1 = 0;
      for (int k = -4; k <= 4; ++k) {
        const int rr = static_cast<int>(std::lround(r + k * n[1])), cc = static_cast<int>(std::lround(c + k * n[0]));
        if (rr < 0 || cc < 0 || rr >= d.rows || cc >= d.cols) continue;
        const double rel = std::abs(d.at<double>(rr, cc) - d0) / d0;
        max_rel = std::max(max_rel, rel);
        if (std::abs(k) <= 1) max_rel_1 = std::max(max_rel_1, rel);
      }
      if (max_rel_1 > 0.05) t.silhouette.at<std::uint8_t>(r, c) = 255;
      else if (max_rel < 0.015 && !v.near_edge.at<std::uint8_t>(r, c)) t.texture.at<std::uint8_t>(r, c) = 255;
    }
  return t;
}

struct ClassScore {
  long long silhouettes = 0, silhouettes_right = 0, textures = 0, textures_right = 0;
  // Silhouette pixels with the object's depth whose larger side faces the object.
  long long object_side = 0, object_side_right = 0;
  double Silhouette() const { return silhouettes ? double(silhouettes_right) / silhouettes : 0; }
  double Texture() const { return textures ? double(textures_right) / textures : 0; }
  double ObjectSide() const { return object_side ? double(object_side_right) / object_side : 0; }
};

ClassScore Classify(const SynthViews& v) {
  const DepthMap at = TruthAtEdges(v);
  const BidirectionalPhotoconsistency pc{PhotoconsistencyOptions()};
  const EdgeConsistency e = pc.Compute(v.ref, v.NeighborPtrs(), at);
  const cv::Mat classes = e.Classify(pc.options().silhouette_ratio);
  const EdgeTruth truth = ClassifyTruth(v, at);
  ClassScore s;
  const cv::Mat& d = v.truth.depth;
  for (int r = 0; r < classes.rows; ++r)
    for (int c = 0; c < classes.cols; ++c) {
      const std::uint8_t k = classes.at<std::uint8_t>(r, c);
      if (truth.silhouette.at<std::uint8_t>(r, c)) {
        ++s.silhouettes;
        s.silhouettes_right += k == kSil;
        // Which side is the object's: the one whose pixel 2 px away along θ
        // has (about) this pixel's true depth.
        const cv::Vec2f n = e.direction.at<cv::Vec2f>(r, c);
        const int rp = static_cast<int>(std::lround(r + 2 * n[1])), cp = static_cast<int>(std::lround(c + 2 * n[0]));
        const int rm = static_cast<int>(std::lround(r - 2 * n[1])), cm = static_cast<int>(std::lround(c - 2 * n[0]));
        if (k != kSil || rp < 0 || rm < 0 || cp < 0 || cm < 0 || rp >= d.rows || rm >= d.rows || cp >= d.cols ||
            cm >= d.cols)
          continue;
        const double d0 = d.at<double>(r, c);
        const bool plus_same = std::abs(d.at<double>(rp, cp) - d0) < 0.02 * d0;
        const bool minus_same = std::abs(d.at<double>(rm, cm) - d0) < 0.02 * d0;
        if (plus_same == minus_same) continue;
        ++s.object_side;
        s.object_side_right += plus_same == (e.c_plus.at<float>(r, c) > e.c_minus.at<float>(r, c));
      } else if (truth.texture.at<std::uint8_t>(r, c)) {
        ++s.textures;
        s.textures_right += k == kTex;
      }
    }
  return s;
}

void Print(const char* name, const ClassScore& s) {
  std::printf("%s: silhouette %.4f of %lld, texture %.4f of %lld, object side %.4f of %lld\n", name, s.Silhouette(),
              s.silhouettes, s.Texture(), s.textures, s.ObjectSide(), s.object_side);
}

TEST(BidirectionalPhotoconsistency, ClassifiesSilhouetteAndTextureEdgesOfCards) {
  const ClassScore s = Classify(MakeCustomViews(CardsScene(), {0, 0, 0.3}, 0.9, 0.4));
  Print("cards", s);
  ASSERT_GT(s.silhouettes, 300);
  ASSERT_GT(s.textures, 2000);
  EXPECT_GE(s.Silhouette(), 0.90);
  EXPECT_GE(s.Texture(), 0.90);
  // The consistent side of a silhouette pixel is the side of the object it belongs to.
  EXPECT_GE(s.ObjectSide(), 0.95);
}

TEST(BidirectionalPhotoconsistency, ClassifiesSilhouetteAndTextureEdgesOfOcclusionScene) {
  // Spheres, boxes and a pillar occluding one another and a textured floor.
  const ClassScore s = Classify(MakeSynthViews("occlusion"));
  Print("occlusion", s);
  ASSERT_GT(s.silhouettes, 300);
  ASSERT_GT(s.textures, 2000);
  EXPECT_GE(s.Silhouette(), 0.90);
  EXPECT_GE(s.Texture(), 0.90);
  EXPECT_GE(s.ObjectSide(), 0.95);
}

TEST(BidirectionalPhotoconsistency, KnownLimitsOnLimbsAndThinObjects) {
  // Where the paper's fronto-parallel plane fails: on a sphere's limb the
  // object's side curves away within the 3 samples, and 1-3 px thin sticks
  // have the background on both sides. Texture edges stay right; silhouettes
  // are guarded at what this implementation reaches (measured 0.87 and 0.77).
  const ClassScore sphere = Classify(MakeSynthViews("sphere"));
  const ClassScore tabletop = Classify(MakeSynthViews("tabletop", 40));
  Print("sphere", sphere);
  Print("tabletop", tabletop);
  EXPECT_GE(sphere.Texture(), 0.93);
  EXPECT_GE(tabletop.Texture(), 0.93);
  EXPECT_GE(sphere.Silhouette(), 0.82);
  EXPECT_GE(tabletop.Silhouette(), 0.70);
}

TEST(BidirectionalPhotoconsistency, CentreConsistencyHoldsOnThinPartsNotBesideThem) {
  // centre_consistency: C0 samples along the edge. On a thin part (the true
  // depth 2 px away on *both* sides is far behind the pixel's: the tabletop's
  // sticks and legs) C0 at the true depth beats max(C+, C−) by the silhouette
  // ratio at a third of the pixels (measured 0.308 of 172; the others are
  // sticks' ends and wider legs where one side still holds); at texture edges
  // (flat depth around) almost never (0.001 of 15860), both sides hold there.
  const SynthViews v = MakeSynthViews("tabletop", 40);
  const DepthMap at = TruthAtEdges(v);
  PhotoconsistencyOptions o;
  o.centre_consistency = true;
  const EdgeConsistency e = BidirectionalPhotoconsistency(o).Compute(v.ref, v.NeighborPtrs(), at);
  ASSERT_EQ(e.c_centre.size(), at.depth.size());
  const EdgeTruth truth = ClassifyTruth(v, at);
  const cv::Mat& d = v.truth.depth;
  long long thin = 0, thin_wins = 0, texture = 0, texture_wins = 0;
  for (int r = 0; r < d.rows; ++r)
    for (int c = 0; c < d.cols; ++c) {
      if (!(at.depth.at<float>(r, c) > 0) || !e.evaluated.at<std::uint8_t>(r, c)) continue;
      const float cp = e.c_plus.at<float>(r, c), cm = e.c_minus.at<float>(r, c), c0 = e.c_centre.at<float>(r, c);
      const float side = std::max(cp, cm);
      const bool wins = c0 - side > o.silhouette_ratio * (c0 + side);
      const cv::Vec2f n = e.direction.at<cv::Vec2f>(r, c);
      const double d0 = d.at<double>(r, c);
      bool behind_both = true;
      for (int sgn : {-1, 1}) {
        const int rr = static_cast<int>(std::lround(r + 2 * sgn * n[1]));
        const int cc = static_cast<int>(std::lround(c + 2 * sgn * n[0]));
        if (rr < 0 || cc < 0 || rr >= d.rows || cc >= d.cols || !(d.at<double>(rr, cc) > 1.1 * d0)) behind_both = false;
      }
      if (behind_both && v.foreground.at<std::uint8_t>(r, c)) {
        ++thin;
        thin_wins += wins;
      } else if (truth.texture.at<std::uint8_t>(r, c)) {
        ++texture;
        texture_wins += wins;
      }
    }
  const double thin_rate = thin ? double(thin_wins) / thin : 0, texture_rate = texture ? double(texture_wins) / texture : 1;
  std::printf("C0 beats both sides: thin-part pixels %.3f of %lld, texture edges %.3f of %lld\n", thin_rate, thin,
              texture_rate, texture);
  ASSERT_GT(thin, 50);
  EXPECT_GT(thin_rate, 0.2);
  EXPECT_LT(texture_rate, 0.01);
  // Off: no C0 map.
  PhotoconsistencyOptions off;
  off.centre_consistency = false;
  EXPECT_TRUE(BidirectionalPhotoconsistency(off).Compute(v.ref, v.NeighborPtrs(), at).c_centre.empty());
}

TEST(BidirectionalPhotoconsistency, RatioAndClassesFollowTheDefinition) {
  EdgeConsistency e;
  e.c_plus = (cv::Mat_<float>(1, 4) << 0.8f, 0.5f, 0.0f, 0.0f);
  e.c_minus = (cv::Mat_<float>(1, 4) << 0.2f, 0.4f, 0.0f, 0.0f);
  e.evaluated = (cv::Mat_<std::uint8_t>(1, 4) << 255, 255, 255, 0);
  e.direction = cv::Mat::zeros(1, 4, CV_32FC2);
  const cv::Mat ratio = e.SilhouetteRatio();
  EXPECT_NEAR(ratio.at<float>(0, 0), 0.6f, 1e-6);  // |0.8 − 0.2| / 1.0
  EXPECT_NEAR(ratio.at<float>(0, 1), 0.1f / 0.9f, 1e-6);
  EXPECT_EQ(ratio.at<float>(0, 2), 0.0f);
  const cv::Mat k = e.Classify(0.3);
  EXPECT_EQ(k.at<std::uint8_t>(0, 0), kSil);
  EXPECT_EQ(k.at<std::uint8_t>(0, 1), kTex);
  EXPECT_EQ(k.at<std::uint8_t>(0, 2), static_cast<std::uint8_t>(EdgeClass::kUnresolved));
  EXPECT_EQ(k.at<std::uint8_t>(0, 3), static_cast<std::uint8_t>(EdgeClass::kNone));
}

TEST(BidirectionalPhotoconsistency, DegenerateInputGivesZeroMaps) {
  const SynthViews v = MakeSynthViews("sphere", 0, 2.0, 160, 90, 480);
  const BidirectionalPhotoconsistency pc{PhotoconsistencyOptions()};
  const auto expect_zero = [](const EdgeConsistency& e, int rows, int cols) {
    ASSERT_EQ(e.c_plus.rows, rows);
    ASSERT_EQ(e.c_plus.cols, cols);
    EXPECT_EQ(cv::countNonZero(e.c_plus), 0);
    EXPECT_EQ(cv::countNonZero(e.c_minus), 0);
  };
  // No depth at all.
  expect_zero(pc.Compute(v.ref, v.NeighborPtrs(), DepthMap(90, 160)), 90, 160);
  // Depth everywhere but no neighbour (and null pointers among them).
  DepthMap full(90, 160);
  full.depth.setTo(1.0f);
  const EdgeConsistency none = pc.Compute(v.ref, {nullptr}, full);
  expect_zero(none, 90, 160);
  // A blank frame: no gradient direction anywhere, so nothing is evaluated.
  ViewImage blank;
  blank.view = v.ref.view;
  blank.image = cv::Mat(90, 160, CV_32FC3, cv::Scalar(0.5, 0.5, 0.5));
  const EdgeConsistency flat = pc.Compute(blank, v.NeighborPtrs(), full);
  expect_zero(flat, 90, 160);
  EXPECT_EQ(cv::countNonZero(flat.evaluated), 0);
  // A depth map of the wrong size is ignored.
  expect_zero(pc.Compute(v.ref, v.NeighborPtrs(), DepthMap(10, 10)), 90, 160);
}

bool SameBits(const cv::Mat& a, const cv::Mat& b) {
  if (a.size() != b.size() || a.type() != b.type()) return false;
  for (int r = 0; r < a.rows; ++r)
    if (std::memcmp(a.ptr(r), b.ptr(r), a.cols * a.elemSize()) != 0) return false;
  return true;
}

TEST(BidirectionalPhotoconsistency, SelectsNeighboursByAngleThinnedToMaxViews) {
  const SynthViews v = MakeSynthViews("occlusion");
  ASSERT_GE(v.neighbors.size(), 6u);
  // Reversed, with a null pointer and the reference itself among them.
  std::vector<const PinholeView*> views = {nullptr, &v.ref.view};
  for (auto it = v.neighbors.rbegin(); it != v.neighbors.rend(); ++it) views.push_back(&it->view);
  PhotoconsistencyOptions o;
  const std::vector<int> all = BidirectionalPhotoconsistency(o).SelectNeighbors(v.ref.view, views);
  ASSERT_EQ(all.size(), v.neighbors.size());
  double last = -1;
  for (int j : all) {
    ASSERT_GE(j, 2);
    const double angle = AngleBetweenDeg(v.ref.view.ViewingDirection(), views[j]->ViewingDirection());
    EXPECT_GE(angle, last);
    last = angle;
  }
  o.max_views = 3;
  const std::vector<int> three = BidirectionalPhotoconsistency(o).SelectNeighbors(v.ref.view, views);
  ASSERT_EQ(three.size(), 3u);
  for (std::size_t k = 0; k < 3; ++k) EXPECT_EQ(three[k], all[k * all.size() / 3]);
}

TEST(BidirectionalPhotoconsistency, AccumulatorOneNeighbourAtATimeIsBitIdenticalToCompute) {
  const SynthViews v = MakeSynthViews("occlusion");
  const DepthMap depth = TruthAtEdges(v);
  for (const int max_views : {0, 5}) {
    PhotoconsistencyOptions o;
    o.max_views = max_views;
    const BidirectionalPhotoconsistency pc(o);
    const EdgeConsistency all = pc.Compute(v.ref, v.NeighborPtrs(), depth);
    std::vector<const PinholeView*> views;
    for (const ViewImage& n : v.neighbors) views.push_back(&n.view);
    PhotoconsistencyAccumulator acc(o);
    acc.Begin(v.ref, depth);
    for (int j : pc.SelectNeighbors(v.ref.view, views)) {
      // The neighbour's frame exists only for its Add (smoothed there: no `smoothed`).
      ViewImage one;
      one.view = v.neighbors[j].view;
      one.image = v.neighbors[j].image.clone();
      acc.Add(one);
    }
    EXPECT_EQ(acc.neighbors_added(), max_views ? max_views : static_cast<int>(v.neighbors.size()));
    const EdgeConsistency streamed = acc.Finish();
    EXPECT_GT(cv::countNonZero(streamed.evaluated), 1000);
    EXPECT_TRUE(SameBits(all.c_plus, streamed.c_plus));
    EXPECT_TRUE(SameBits(all.c_minus, streamed.c_minus));
    EXPECT_TRUE(SameBits(all.direction, streamed.direction));
    EXPECT_TRUE(SameBits(all.evaluated, streamed.evaluated));
  }
  // Nothing added: nothing evaluated; the accumulator starts over on Begin.
  PhotoconsistencyAccumulator acc{PhotoconsistencyOptions()};
  acc.Begin(v.ref, depth);
  acc.Add(v.ref);  // the reference itself does not count
  const EdgeConsistency none = acc.Finish();
  EXPECT_EQ(acc.neighbors_added(), 0);
  EXPECT_EQ(cv::countNonZero(none.evaluated), 0);
  EXPECT_EQ(cv::countNonZero(none.c_plus), 0);
}

TEST(BidirectionalPhotoconsistency, EightPixelsAtOnceGiveTheBitsOfOneAtATime) {
  // The AVX2 path (options.simd, where the CPU has it) against the scalar one,
  // with chroma weighted and not, with C0 and without, and with depths off the
  // truth so that samples leave the neighbours and ρ spans (0, 1].
  const SynthViews v = MakeSynthViews("occlusion");
  DepthMap depth = TruthAtEdges(v);
  for (int r = 0; r < depth.depth.rows; ++r)
    for (int c = 0; c < depth.depth.cols; ++c)
      if ((r * 7 + c * 3) % 5 == 0) depth.depth.at<float>(r, c) *= 0.6f + 0.1f * static_cast<float>(c % 9);
  for (const double chroma : {0.5, 1.0})
    for (const bool centre : {true, false}) {
      PhotoconsistencyOptions o;
      o.chroma_weight = chroma;
      o.centre_consistency = centre;
      const EdgeConsistency simd = BidirectionalPhotoconsistency(o).Compute(v.ref, v.NeighborPtrs(), depth);
      o.simd = false;
      const EdgeConsistency scalar = BidirectionalPhotoconsistency(o).Compute(v.ref, v.NeighborPtrs(), depth);
      EXPECT_GT(cv::countNonZero(scalar.c_plus), 1000);
      EXPECT_TRUE(SameBits(simd.c_plus, scalar.c_plus));
      EXPECT_TRUE(SameBits(simd.c_minus, scalar.c_minus));
      EXPECT_TRUE(SameBits(simd.evaluated, scalar.evaluated));
      if (centre) EXPECT_TRUE(SameBits(simd.c_centre, scalar.c_centre));
      // Some sides are partly outside the neighbours or far off: ρ small but counted.
      double lo = 1;
      for (int r = 0; r < scalar.c_plus.rows; ++r)
        for (int c = 0; c < scalar.c_plus.cols; ++c)
          if (scalar.evaluated.at<std::uint8_t>(r, c)) lo = std::min<double>(lo, scalar.c_plus.at<float>(r, c));
      EXPECT_LT(lo, 0.01);
    }
}

TEST(ColourDifference, SplitsLumaFromChroma) {
  const Eigen::Vector3f a(0.3f, 0.5f, 0.7f);
  // Weight 1: the plain squared RGB distance, exactly.
  const Eigen::Vector3f b(0.1f, 0.6f, 0.2f);
  EXPECT_EQ(ColourDifference2(a, b, 1.0f), (a - b).squaredNorm());
  // A grey difference is all luma: 3·k² at any chroma weight.
  const Eigen::Vector3f grey = a + Eigen::Vector3f::Constant(0.04f);
  EXPECT_NEAR(ColourDifference2(grey, a, 0.0f), 3 * 0.04f * 0.04f, 1e-7f);
  EXPECT_NEAR(ColourDifference2(grey, a, 0.5f), 3 * 0.04f * 0.04f, 1e-7f);
  // A difference that leaves Rec. 601 luma (BGR weights 0.114, 0.587, 0.299)
  // unchanged is all chroma: scaled by the weight, zero at weight 0.
  const Eigen::Vector3f e(0.587f * 0.1f, -0.114f * 0.1f, 0.0f);  // 0.114·e_B + 0.587·e_G = 0
  EXPECT_NEAR(ColourDifference2(a + e, a, 0.0f), 0.0f, 1e-9f);
  EXPECT_NEAR(ColourDifference2(a + e, a, 0.25f), 0.25f * e.squaredNorm(), 1e-7f);
}

TEST(BidirectionalPhotoconsistency, OptionsAreChecked) {
  PhotoconsistencyOptions o;
  EXPECT_NO_THROW(o.Check());
  o.sigma_p = 0;
  EXPECT_THROW(o.Check(), OptionError);
  o = PhotoconsistencyOptions();
  o.samples_per_side = 0;
  EXPECT_THROW(BidirectionalPhotoconsistency{o}, OptionError);
  o = PhotoconsistencyOptions();
  o.silhouette_ratio = 1.0;
  EXPECT_THROW(o.Check(), OptionError);
  o = PhotoconsistencyOptions();
  o.max_view_angle_deg = 0;
  EXPECT_THROW(o.Check(), OptionError);
  o = PhotoconsistencyOptions();
  o.chroma_weight = 1.5;
  EXPECT_THROW(o.Check(), OptionError);
}

}  // namespace
}  // namespace lfrecon
