#include "propagation/depth_propagator.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cstdio>

#include "../depth/synth_views.h"
#include "propagation/dense_consistency.h"
#include "util/error.h"

namespace lfrecon {
namespace {

using testing::MakeCustomViews;
using testing::SynthViews;

constexpr std::uint8_t kFg = static_cast<std::uint8_t>(DepthLabel::kForeground);
constexpr std::uint8_t kBg = static_cast<std::uint8_t>(DepthLabel::kBackground);

// A textured-boundary, smooth-interior object: a textured panel (0.30 × 0.22 m)
// turned 25° about the vertical, with a flat-coloured panel (0.20 × 0.13 m)
// 1 mm in front of its middle, at 0.9 m in front of a textured wall at 1.9 m.
// The flat panel's interior has no image gradient at all: its depth can only
// come from the edges around it.
constexpr int kFlatPanel = 1;  // primitive id of the flat panel
synth::Scene FramedPanelScene() {
  synth::Scene s("framed_panel");
  s.set_foreground_bbox({Eigen::Vector3d(-0.2, -0.25, 0.1), Eigen::Vector3d(0.2, 0.25, 0.5)});
  const Eigen::Matrix3d R = Eigen::AngleAxisd(25 * M_PI / 180, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const Eigen::Vector3d u = R * Eigen::Vector3d::UnitY(), normal = R * Eigen::Vector3d::UnitX();
  const Eigen::Vector3d c(0, 0, 0.3);
  s.Add(synth::Primitive::Rect(c, u, Eigen::Vector3d::UnitZ(), 0.15, 0.11,
                               synth::Material::Noise({0.45f, 0.15f, 0.1f}, {1.0f, 0.85f, 0.55f}, 0.008))
            .Foreground());
  s.Add(synth::Primitive::Rect(c + 0.001 * normal, u, Eigen::Vector3d::UnitZ(), 0.1, 0.065,
                               synth::Material::Flat({0.55f, 0.7f, 0.85f}))
            .Foreground());
  s.Add(synth::Primitive::Rect({-1.0, 0, 0.3}, Eigen::Vector3d::UnitY(), Eigen::Vector3d::UnitZ(), 2.0, 1.5,
                               synth::Material::Noise({0.2f, 0.3f, 0.2f}, {0.8f, 0.9f, 0.7f}, 0.03)));
  s.Add(synth::Primitive::Sphere(Eigen::Vector3d::Zero(), 3.0,
                                 synth::Material::Noise({0.35f, 0.42f, 0.55f}, {0.8f, 0.82f, 0.86f}, 0.2)));
  return s;
}

struct Fixture {
  SynthViews v;
  DepthMap sparse;
};

const Fixture& Panel() {
  static const Fixture f = [] {
    Fixture x{MakeCustomViews(FramedPanelScene(), {0, 0, 0.3}, 0.9, 0.35), {}};
    // The depth stage's own sparse estimate (§3.1) stands in for the filtered map.
    x.sparse = GradientDepthEstimator(GradientDepthOptions()).Estimate(x.v.ref, x.v.NeighborPtrs(), x.v.volume);
    return x;
  }();
  return f;
}

// Pixels of the flat panel at least `margin` px from any other primitive.
cv::Mat FlatInterior(const SynthViews& v, int margin) {
  cv::Mat flat = v.truth.labels == kFlatPanel, inner;
  cv::erode(flat, inner, cv::Mat::ones(2 * margin + 1, 2 * margin + 1, CV_8U));
  return inner;
}

double ShareWithin(const SynthViews& v, const DepthMap& m, const cv::Mat& mask, double tol, long long* n_out = nullptr) {
  long long n = 0, ok = 0;
  for (int r = 0; r < mask.rows; ++r)
    for (int c = 0; c < mask.cols; ++c) {
      if (!mask.at<std::uint8_t>(r, c)) continue;
      ++n;
      const double t = v.truth.depth.at<double>(r, c);
      ok += std::abs(m.depth.at<float>(r, c) - t) <= tol * t;
    }
  if (n_out) *n_out = n;
  return n ? double(ok) / n : 0;
}

TEST(DepthPropagator, SmoothInteriorFromTexturedBoundaryWithinOnePercent) {
  const Fixture& f = Panel();
  const cv::Mat interior = FlatInterior(f.v, 3);
  ASSERT_GT(cv::countNonZero(interior), 2000);
  // The interior has no sparse depth of its own.
  cv::Mat has_depth = f.sparse.depth > 0, inside_with_depth;
  cv::bitwise_and(has_depth, interior, inside_with_depth);
  ASSERT_LT(cv::countNonZero(inside_with_depth), cv::countNonZero(interior) / 50);

  const DenseDepthResult res =
      DepthPropagator(PropagationOptions()).Run(f.v.ref, f.v.NeighborPtrs(), f.sparse, f.v.volume);
  long long n = 0;
  const double within1 = ShareWithin(f.v, res.dense, interior, 0.01, &n);
  const double within05 = ShareWithin(f.v, res.dense, interior, 0.005);
  // The paper's constant model (eq. 10) on the same input, for comparison.
  const DepthMap paper = DensifyDepth(f.v.ref, f.v.NeighborPtrs(), f.sparse, f.v.volume, PaperPropagationOptions());
  std::printf("flat interior (%lld px): within 1%% %.4f, within 0.5%% %.4f; paper's eq. 10 alone: within 1%% %.4f\n", n,
              within1, within05, ShareWithin(f.v, paper, interior, 0.01));
  EXPECT_GE(within1, 0.90);
  // All of the interior is foreground.
  long long fg = 0;
  for (int r = 0; r < interior.rows; ++r)
    for (int c = 0; c < interior.cols; ++c)
      fg += interior.at<std::uint8_t>(r, c) && res.dense.label.at<std::uint8_t>(r, c) == kFg;
  EXPECT_EQ(fg, n);
}

TEST(DepthPropagator, BackgroundDoesNotBleedIntoTheObjectAcrossItsSilhouette) {
  const Fixture& f = Panel();
  const DepthMap dense = DensifyDepth(f.v.ref, f.v.NeighborPtrs(), f.sparse, f.v.volume, PropagationOptions());
  // A band along the object's occluding contour, on the object's side: object
  // pixels 2-6 px from the nearest background pixel (the contour pixel itself
  // and its neighbour mix object and wall, and are left out).
  cv::Mat object = f.v.foreground.clone(), dist;
  cv::distanceTransform(object, dist, cv::DIST_L2, 3);
  long long band = 0, bled = 0, wrong_side = 0, accurate = 0, with_depth = 0;
  for (int r = 0; r < dist.rows; ++r)
    for (int c = 0; c < dist.cols; ++c) {
      const float dd = dist.at<float>(r, c);
      if (!object.at<std::uint8_t>(r, c) || dd < 2 || dd > 6) continue;
      ++band;
      const double t = f.v.truth.depth.at<double>(r, c);
      const float e = dense.depth.at<float>(r, c);
      wrong_side += dense.label.at<std::uint8_t>(r, c) == kBg;
      with_depth += e > 0;
      bled += e > 1.2 * t;  // the wall is 2× further away
      accurate += std::abs(e - t) <= 0.01 * t;
    }
  std::printf("contour band %lld px: background-labelled %lld, background depth %lld, within 1%% %.4f\n", band,
              wrong_side, bled, band ? double(accurate) / band : 0);
  ASSERT_GT(band, 500);
  EXPECT_EQ(wrong_side, 0);
  EXPECT_EQ(bled, 0);
  // The dense consistency check may drop a few (no evidence, not wrong evidence).
  EXPECT_GE(with_depth, band * 97 / 100);
  EXPECT_GE(static_cast<double>(accurate) / band, 0.90);
}

TEST(DenseConsistency, RemovesAHaloOfObjectDepthOverTexturedBackgroundAndKeepsTheObject) {
  const Fixture& f = Panel();
  // The truth as a dense map, plus a halo: wall pixels up to 12 px from the
  // object given the depth of the object's nearest pixel, labelled
  // foreground — what propagation does where the wall has no depth of its own.
  DepthMap dense(f.v.ref.image.rows, f.v.ref.image.cols);
  cv::Mat wall = f.v.foreground == 0, dist, nearest;
  cv::distanceTransform(wall, dist, nearest, cv::DIST_L2, 5, cv::DIST_LABEL_PIXEL);
  std::vector<cv::Point> seed(1);  // label -> the object pixel it came from
  for (int r = 0; r < wall.rows; ++r)
    for (int c = 0; c < wall.cols; ++c)
      if (!wall.at<std::uint8_t>(r, c)) {
        const int k = nearest.at<int>(r, c);
        if (k >= static_cast<int>(seed.size())) seed.resize(k + 1);
        seed[k] = cv::Point(c, r);
      }
  long long object = 0, halo = 0;
  for (int r = 0; r < wall.rows; ++r)
    for (int c = 0; c < wall.cols; ++c) {
      cv::Point from(c, r);
      if (wall.at<std::uint8_t>(r, c)) {
        if (dist.at<float>(r, c) > 12) continue;
        from = seed[nearest.at<int>(r, c)];
        ++halo;
      } else {
        ++object;
      }
      dense.depth.at<float>(r, c) = static_cast<float>(f.v.truth.depth.at<double>(from.y, from.x));
      dense.confidence.at<float>(r, c) = 0.5f;
      dense.label.at<std::uint8_t>(r, c) = kFg;
    }
  ASSERT_GT(halo, 2000);
  CheckDenseConsistency(f.v.ref, f.v.NeighborPtrs(), DenseConsistencyOptions(), &dense);
  // Object pixels whose patch lies on the object (≥ 3 px from the wall; nearer
  // ones mix wall colours, and the pipeline exempts the edge pixels there).
  cv::Mat object_mask = f.v.foreground.clone(), object_dist;
  cv::distanceTransform(object_mask, object_dist, cv::DIST_L2, 3);
  long long halo_kept = 0, inner = 0, inner_kept = 0;
  for (int r = 0; r < wall.rows; ++r)
    for (int c = 0; c < wall.cols; ++c) {
      const bool kept = dense.depth.at<float>(r, c) > 0;
      if (wall.at<std::uint8_t>(r, c)) {
        halo_kept += kept;
      } else if (object_dist.at<float>(r, c) >= 3) {
        ++inner;
        inner_kept += kept;
      }
    }
  std::printf("halo %lld px, kept %.3f; object %lld px (%lld >= 3 px inside), kept %.3f\n", halo,
              double(halo_kept) / halo, object, inner, double(inner_kept) / inner);
  EXPECT_LT(halo_kept, halo / 10);           // the halo goes (0.017 kept)
  EXPECT_GE(inner_kept, inner * 92 / 100);  // the object stays (0.946: its fine, high-contrast
                                            // texture loses a little to bilinear sampling)
  // Off: nothing changes.
  DenseConsistencyOptions off;
  off.views = 0;
  DepthMap copy = dense;
  copy.depth = dense.depth.clone();
  CheckDenseConsistency(f.v.ref, f.v.NeighborPtrs(), off, &copy);
  EXPECT_EQ(cv::countNonZero(copy.depth != dense.depth), 0);
}

TEST(DepthPropagator, SplatGoesToTheConsistentSideAndTheStrongestWins) {
  // Hand-made edge pixels on a 7×7 map, θ = +x (positive side to the right).
  DepthMap m(7, 7);
  EdgeConsistency e;
  e.c_plus = cv::Mat::zeros(7, 7, CV_32F);
  e.c_minus = cv::Mat::zeros(7, 7, CV_32F);
  e.direction = cv::Mat::zeros(7, 7, CV_32FC2);
  e.evaluated = cv::Mat::zeros(7, 7, CV_8U);
  const auto edge = [&](int r, int c, float d, std::uint8_t label, float cp, float cm, cv::Vec2f dir) {
    m.depth.at<float>(r, c) = d;
    m.confidence.at<float>(r, c) = 1.0f;
    m.label.at<std::uint8_t>(r, c) = label;
    e.c_plus.at<float>(r, c) = cp;
    e.c_minus.at<float>(r, c) = cm;
    e.direction.at<cv::Vec2f>(r, c) = dir;
    e.evaluated.at<std::uint8_t>(r, c) = 255;
  };
  edge(1, 3, 1.0f, kFg, 0.9f, 0.1f, {1, 0});  // silhouette: object to the right
  edge(3, 3, 2.0f, kBg, 0.6f, 0.5f, {1, 0});  // texture edge: both sides
  // Two edge pixels splat into (5, 3): from (5, 2) with C+ = 0.4, from (5, 4) with C− = 0.7.
  edge(5, 2, 1.5f, kFg, 0.4f, 0.35f, {1, 0});
  edge(5, 4, 1.7f, kFg, 0.8f, 0.7f, {1, 0});
  PropagationOptions paper = PaperPropagationOptions();
  PropagationOptions ours;
  const SplatMaps two = DepthPropagator(paper).Splat(m, e);
  const SplatMaps one = DepthPropagator(ours).Splat(m, e);
  // Paper: both neighbours get D(p), with C+ on the right and C− on the left.
  EXPECT_FLOAT_EQ(two.depth_fg.at<float>(1, 4), 1.0f);
  EXPECT_FLOAT_EQ(two.confidence_fg.at<float>(1, 4), 0.9f);
  EXPECT_FLOAT_EQ(two.confidence_fg.at<float>(1, 2), 0.1f);
  EXPECT_FLOAT_EQ(two.confidence_fg.at<float>(1, 3), 0.9f);  // the edge pixel keeps max(C+, C−)
  // Ours: at a silhouette only the consistent side, and the edge pixel feeds the filter through its splat alone.
  EXPECT_FLOAT_EQ(one.confidence_fg.at<float>(1, 4), 0.9f);
  EXPECT_FLOAT_EQ(one.confidence_fg.at<float>(1, 2), 0.0f);
  EXPECT_FLOAT_EQ(one.confidence_fg.at<float>(1, 3), 0.0f);
  EXPECT_FLOAT_EQ(one.edge_depth.at<float>(1, 3), 1.0f);
  // Texture edge (ratio 0.09): both sides, into the background maps.
  for (const SplatMaps* s : {&two, &one}) {
    EXPECT_FLOAT_EQ(s->depth_bg.at<float>(3, 2), 2.0f);
    EXPECT_FLOAT_EQ(s->confidence_bg.at<float>(3, 2), 0.5f);
    EXPECT_FLOAT_EQ(s->confidence_bg.at<float>(3, 4), 0.6f);
    EXPECT_EQ(s->confidence_fg.at<float>(3, 4), 0.0f);
    // Conflict at (5, 3): the higher confidence (0.7 from the right) wins.
    EXPECT_FLOAT_EQ(s->depth_fg.at<float>(5, 3), 1.7f);
    EXPECT_FLOAT_EQ(s->confidence_fg.at<float>(5, 3), 0.7f);
  }
}

// Hand-made inputs of Splat: a filtered map and its edges' C± (and C0 when
// `centre` is set), every edge pixel's gradient along +x.
struct EdgeMaps {
  DepthMap map;
  EdgeConsistency edges;
  EdgeMaps(int rows, int cols, bool centre) : map(rows, cols) {
    edges.c_plus = cv::Mat::zeros(rows, cols, CV_32F);
    edges.c_minus = cv::Mat::zeros(rows, cols, CV_32F);
    if (centre) edges.c_centre = cv::Mat::zeros(rows, cols, CV_32F);
    edges.direction = cv::Mat::zeros(rows, cols, CV_32FC2);
    edges.evaluated = cv::Mat::zeros(rows, cols, CV_8U);
  }
  void Edge(int r, int c, float d, std::uint8_t label, float cp, float cm, float c0 = 0) {
    map.depth.at<float>(r, c) = d;
    map.confidence.at<float>(r, c) = 1.0f;
    map.label.at<std::uint8_t>(r, c) = label;
    edges.c_plus.at<float>(r, c) = cp;
    edges.c_minus.at<float>(r, c) = cm;
    if (!edges.c_centre.empty()) edges.c_centre.at<float>(r, c) = c0;
    edges.direction.at<cv::Vec2f>(r, c) = {1, 0};
    edges.evaluated.at<std::uint8_t>(r, c) = 255;
  }
};

TEST(DepthPropagator, ARodTwoPixelsWideKeepsItsDepthWhereItsSplatsCannotLand) {
  // A vertical rod two pixels wide (columns 20 and 21) before a background
  // with texture edges every 5 px: each rod pixel is a silhouette edge whose
  // consistent side is the other rod pixel, an edge pixel too.
  const int rows = 40, cols = 40;
  cv::Mat image(rows, cols, CV_32FC3, cv::Scalar(0.5, 0.5, 0.5));
  EdgeMaps in(rows, cols, false);
  const DepthMap& m = in.map;
  const EdgeConsistency& e = in.edges;
  for (int r = 0; r < rows; ++r) {
    image.at<cv::Vec3f>(r, 20) = image.at<cv::Vec3f>(r, 21) = cv::Vec3f(0.1f, 0.1f, 0.1f);
    in.Edge(r, 20, 0.6f, kFg, 0.9f, 0.1f);  // object to the right
    in.Edge(r, 21, 0.6f, kFg, 0.1f, 0.9f);  // object to the left
    for (int c = 2; c < cols; c += 5)
      if (c < 18 || c > 23) in.Edge(r, c, 2.0f, kBg, 0.8f, 0.8f);  // background texture
  }
  PropagationOptions on, off;
  on.blocked_silhouettes_keep_depth = true;
  off.blocked_silhouettes_keep_depth = false;
  const SplatMaps a = DepthPropagator(off).Splat(m, e), b = DepthPropagator(on).Splat(m, e);
  for (int c = 20; c <= 21; ++c) {
    EXPECT_FLOAT_EQ(a.confidence_fg.at<float>(10, c), 0.0f) << c;  // the rod reaches the filter nowhere
    EXPECT_FLOAT_EQ(b.confidence_fg.at<float>(10, c), 0.9f) << c;  // it keeps max(C+, C−)
    EXPECT_FLOAT_EQ(b.depth_fg.at<float>(10, c), 0.6f) << c;
  }
  // Densified: without the exception the background wins on the rod (fusion
  // would carve it); with it the rod keeps its own depth.
  const DepthMap da = DepthPropagator(off).Filter(image, a), db = DepthPropagator(on).Filter(image, b);
  int rod_bg_off = 0, rod_fg_on = 0;
  for (int r = 0; r < rows; ++r)
    for (int c = 20; c <= 21; ++c) {
      rod_bg_off += da.label.at<std::uint8_t>(r, c) == kBg;
      rod_fg_on += db.label.at<std::uint8_t>(r, c) == kFg && std::abs(db.depth.at<float>(r, c) - 0.6f) < 1e-4f;
    }
  EXPECT_EQ(rod_bg_off, 2 * rows);
  EXPECT_EQ(rod_fg_on, 2 * rows);
  // A silhouette whose splat lands (column 20's right neighbour is no edge) still feeds the filter only through it.
  DepthMap single = m;
  EdgeConsistency e1 = e;
  for (int r = 0; r < rows; ++r) e1.evaluated.at<std::uint8_t>(r, 21) = 0;
  const SplatMaps s1 = DepthPropagator(on).Splat(single, e1);
  EXPECT_FLOAT_EQ(s1.confidence_fg.at<float>(10, 20), 0.0f);
  EXPECT_FLOAT_EQ(s1.confidence_fg.at<float>(10, 21), 0.9f);
}

TEST(DepthPropagator, ARodOnePixelWideKeepsItsDepthWhereItHoldsAlongTheEdge) {
  // A vertical rod one pixel wide (column 20) before a background with texture
  // edges every 5 px: both sides of the rod see the background, so C+ and C−
  // are low at its depth (0.02, 0.1) and it loses to the background; C0 along
  // the rod (PhotoconsistencyOptions::centre_consistency) is 0.8, and the rod
  // keeps its own depth and side after the filter without spreading to its
  // neighbours. A background-labelled pixel that passes the same test is left
  // to the filter (the rule serves foreground parts).
  const int rows = 40, cols = 40;
  cv::Mat image(rows, cols, CV_32FC3, cv::Scalar(0.5, 0.5, 0.5));
  EdgeMaps in(rows, cols, true);
  const DepthMap& m = in.map;
  const EdgeConsistency& e = in.edges;
  for (int r = 0; r < rows; ++r) {
    image.at<cv::Vec3f>(r, 20) = cv::Vec3f(0.1f, 0.1f, 0.1f);
    in.Edge(r, 20, 0.6f, kFg, 0.02f, 0.1f, 0.8f);  // a silhouette (ratio 0.67): it feeds the filter only through its splat
    for (int c = 2; c < cols; c += 5)
      if (c < 18 || c > 22) in.Edge(r, c, 2.0f, kBg, 0.8f, 0.8f, 0.8f);  // texture: C0 does not beat the sides
  }
  in.Edge(5, 32, 2.5f, kBg, 0.1f, 0.1f, 0.9f);  // a background pixel that passes the test
  const DepthPropagator propagator{PropagationOptions{}};
  const SplatMaps splats = propagator.Splat(m, e);
  ASSERT_EQ(splats.thin_confidence.size(), m.depth.size());
  EXPECT_FLOAT_EQ(splats.thin_confidence.at<float>(10, 20), 0.8f);
  EXPECT_FLOAT_EQ(splats.thin_confidence.at<float>(10, 17), 0.0f);  // texture
  EXPECT_FLOAT_EQ(splats.thin_confidence.at<float>(5, 32), 0.0f);   // background-labelled
  // Without C0 (photoconsistency with centre_consistency off leaves c_centre empty).
  EdgeConsistency without = e;
  without.c_centre = cv::Mat();
  const DepthMap dense = propagator.Filter(image, splats);
  const DepthMap plain = propagator.Filter(image, propagator.Splat(m, without));
  const auto count = [&](const DepthMap& d, int col, bool own_depth) {
    int n = 0;
    for (int r = 0; r < rows; ++r)
      n += d.label.at<std::uint8_t>(r, col) == kFg && (!own_depth || std::abs(d.depth.at<float>(r, col) - 0.6f) < 1e-6f);
    return n;
  };
  EXPECT_EQ(count(dense, 20, true), rows);
  for (int r = 0; r < rows; ++r) EXPECT_FLOAT_EQ(dense.confidence.at<float>(r, 20), 0.8f) << r;
  EXPECT_LT(count(plain, 20, true), rows / 2);
  // Nothing spreads from it: the pixels beside the rod are as they are without C0.
  for (int c : {18, 19, 21, 22}) EXPECT_EQ(count(dense, c, false), count(plain, c, false)) << c;
}

TEST(DepthPropagator, FilterReproducesAPlaneFromItsEdgesAndKeepsSidesApart) {
  // Inverse depth affine in the pixel coordinates (a plane) on a frame of
  // foreground pixels around a flat 60×60 square, and a background square to its right.
  const int rows = 100, cols = 160;
  cv::Mat image(rows, cols, CV_32FC3, cv::Scalar(0.3, 0.3, 0.3));
  cv::rectangle(image, cv::Rect(20, 20, 60, 60), cv::Scalar(0.6, 0.5, 0.4), cv::FILLED);
  cv::rectangle(image, cv::Rect(100, 20, 40, 60), cv::Scalar(0.1, 0.7, 0.2), cv::FILLED);
  // Depth of a plane: its inverse is affine in the pixel coordinates.
  const auto plane = [](int r, int c) { return 1.0f / (0.8f + 0.002f * c - 0.001f * r); };
  SplatMaps s = SplatMaps::Zeros(rows, cols);
  for (int r = 20; r < 80; ++r)
    for (int c = 20; c < 80; ++c)
      if (r < 23 || r >= 77 || c < 23 || c >= 77) {  // a 3 px frame inside the square
        s.depth_fg.at<float>(r, c) = plane(r, c);
        s.confidence_fg.at<float>(r, c) = 0.8f;
      }
  for (int r = 20; r < 80; ++r)
    for (int c = 100; c < 140; c += 13) {  // background columns inside the right square
      s.depth_bg.at<float>(r, c) = 3.0f;
      s.confidence_bg.at<float>(r, c) = 0.8f;
    }
  const DepthMap out = DepthPropagator(PropagationOptions()).Filter(image, s);
  double worst = 0;
  for (int r = 26; r < 74; ++r)
    for (int c = 26; c < 74; ++c) {
      ASSERT_EQ(out.label.at<std::uint8_t>(r, c), kFg) << r << "," << c;
      const double t = plane(r, c);
      worst = std::max(worst, std::abs(out.depth.at<float>(r, c) - t) / t);
    }
  std::printf("plane from its frame: worst relative error %.2e\n", worst);
  EXPECT_LT(worst, 1e-3);
  for (int r = 22; r < 78; ++r)
    for (int c = 102; c < 138; ++c) {
      ASSERT_EQ(out.label.at<std::uint8_t>(r, c), kBg) << r << "," << c;
      ASSERT_NEAR(out.depth.at<float>(r, c), 3.0f, 1e-3);
    }
  // Final confidence is |C'_fg − C'_bg| and lies in [0, 1].
  double min_c = 0, max_c = 0;
  cv::minMaxLoc(out.confidence, &min_c, &max_c);
  EXPECT_GE(min_c, 0.0);
  EXPECT_LE(max_c, 1.0);
}

TEST(DepthPropagator, ExtrapolationBeyondTheSupportLosesConfidenceAndLinesKeepTheirs) {
  // A plain frame (nothing stops the filter) and no background support.
  // Surface: foreground depth on a filled band of columns 20-49. Rod: a
  // single column (130) of foreground edge pixels with depths of their own.
  const int rows = 100, cols = 160;
  const cv::Mat image(rows, cols, CV_32FC3, cv::Scalar(0.4, 0.4, 0.4));
  SplatMaps band = SplatMaps::Zeros(rows, cols), rod = SplatMaps::Zeros(rows, cols);
  for (int r = 0; r < rows; ++r) {
    for (int c = 20; c < 50; ++c) {
      band.depth_fg.at<float>(r, c) = 0.8f;
      band.confidence_fg.at<float>(r, c) = 0.8f;
    }
    rod.depth_fg.at<float>(r, 130) = 0.9f;
    rod.confidence_fg.at<float>(r, 130) = 0.8f;
    rod.edge_label.at<std::uint8_t>(r, 130) = kFg;
    rod.edge_depth.at<float>(r, 130) = 0.9f;
  }
  PropagationOptions off;
  off.extrapolation_m0 = 0;
  PropagationOptions on = off;
  on.extrapolation_m0 = 2;
  const auto conf = [](const DepthMap& m, int c) { return m.confidence.at<float>(50, c); };
  {
    const DepthMap a = DepthPropagator(off).Filter(image, band), b = DepthPropagator(on).Filter(image, band);
    // Inside the band, away from its ends: unchanged.
    for (int c = 25; c < 45; ++c) ASSERT_FLOAT_EQ(conf(b, c), conf(a, c)) << c;
    // 30 px beyond the band's edge the plain filter still says foreground;
    // the extrapolation test leaves under 5 % of that confidence.
    ASSERT_EQ(a.label.at<std::uint8_t>(50, 80), kFg);
    EXPECT_GT(conf(a, 80), 1e-3);
    EXPECT_LT(conf(b, 80), 0.05 * conf(a, 80));
    std::printf("30 px beyond the band: confidence %.2e without the test, %.2e with it\n", conf(a, 80), conf(b, 80));
  }
  {
    // The rod's own pixels and their neighbours (within the 2 px floor) keep their confidence and depth.
    const DepthMap a = DepthPropagator(off).Filter(image, rod), b = DepthPropagator(on).Filter(image, rod);
    for (int c = 129; c <= 131; ++c) {
      EXPECT_FLOAT_EQ(conf(b, c), conf(a, c)) << c;
      EXPECT_FLOAT_EQ(b.depth.at<float>(50, c), a.depth.at<float>(50, c)) << c;
    }
  }
  // A zero floor would divide by a zero spread on a line: refused.
  PropagationOptions bad = on;
  bad.extrapolation_floor_px = 0;
  EXPECT_THROW(bad.Check(), OptionError);
}

TEST(DepthPropagator, ContestedForegroundEdgesKeepTheirDepthClearLossesDoNot) {
  // A textured background: background support every 3 px. Column 80 is a
  // part one pixel wide: foreground edge pixels (depth 0.9) whose own splats
  // the propagation dropped (silhouette pixels feed the filter nothing), with
  // foreground support beside them in column 81 whose confidence grows from
  // 0 (row 0) to 0.8 (last row), so the background wins row 0 clearly, the
  // last rows not at all, and some rows between narrowly. Column 40: a
  // foreground edge pixel with no support at all (a clear loss).
  const int rows = 60, cols = 160;
  cv::Mat image(rows, cols, CV_32FC3, cv::Scalar(0.4, 0.4, 0.4));
  image.colRange(80, 82).setTo(cv::Scalar(0.6, 0.6, 0.6));  // the part's own colour
  SplatMaps s = SplatMaps::Zeros(rows, cols);
  for (int r = 0; r < rows; ++r) {
    for (int c = 1; c < cols; c += 3) {
      if (c == 40 || c == 79 || c == 82) continue;
      s.depth_bg.at<float>(r, c) = 3.0f;
      s.confidence_bg.at<float>(r, c) = 0.8f;
    }
    for (int c : {40, 80}) {
      s.edge_label.at<std::uint8_t>(r, c) = kFg;
      s.edge_depth.at<float>(r, c) = 0.9f;
    }
    s.depth_fg.at<float>(r, 81) = 0.9f;
    s.confidence_fg.at<float>(r, 81) = 0.8f * r / (rows - 1);
  }
  PropagationOptions off;
  off.keep_contested_foreground = false;
  const DepthMap a = DepthPropagator(off).Filter(image, s), b = DepthPropagator(PropagationOptions()).Filter(image, s);
  int kept = 0;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      if (c == 80 && a.label.at<std::uint8_t>(r, c) == kBg && b.label.at<std::uint8_t>(r, c) == kFg) {
        EXPECT_FLOAT_EQ(b.depth.at<float>(r, c), 0.9f) << r;  // its own depth, full confidence
        EXPECT_FLOAT_EQ(b.confidence.at<float>(r, c), 1.0f) << r;
        ++kept;
        continue;
      }
      // Everything else as without the rule.
      ASSERT_EQ(b.label.at<std::uint8_t>(r, c), a.label.at<std::uint8_t>(r, c)) << r << "," << c;
      ASSERT_FLOAT_EQ(b.depth.at<float>(r, c), a.depth.at<float>(r, c)) << r << "," << c;
    }
  }
  std::printf("column 80: %d of %d rows kept their own foreground depth\n", kept, rows);
  EXPECT_GE(kept, 3);
  EXPECT_LT(kept, rows / 2);
  // Clear losses stay background: the unsupported column, and the rod where its support is weakest.
  for (int r = 0; r < rows; ++r) EXPECT_EQ(b.label.at<std::uint8_t>(r, 40), kBg) << r;
  EXPECT_EQ(b.label.at<std::uint8_t>(0, 80), kBg);
  EXPECT_EQ(b.label.at<std::uint8_t>(rows - 1, 80), kFg);  // won outright, with or without the rule
  EXPECT_EQ(a.label.at<std::uint8_t>(rows - 1, 80), kFg);
  // The paper's reading has it off.
  EXPECT_FALSE(PaperPropagationOptions().keep_contested_foreground);
}

TEST(DepthPropagator, EdgeCasesGiveDefinedOutput) {
  const SynthViews v = testing::MakeSynthViews("sphere", 0, 2.0, 160, 90, 480);
  const auto expect_empty = [](const DepthMap& m, int rows, int cols) {
    ASSERT_EQ(m.depth.rows, rows);
    ASSERT_EQ(m.depth.cols, cols);
    ASSERT_EQ(m.depth.type(), CV_32F);
    ASSERT_EQ(m.confidence.type(), CV_32F);
    ASSERT_EQ(m.label.type(), CV_8U);
    EXPECT_EQ(cv::countNonZero(m.depth), 0);
    EXPECT_EQ(cv::countNonZero(m.confidence), 0);
    EXPECT_EQ(cv::countNonZero(m.label), 0);
  };
  const PropagationOptions o;
  // No edges: a blank frame (and no depth).
  ViewImage blank;
  blank.view = v.ref.view;
  blank.image = cv::Mat(90, 160, CV_32FC3, cv::Scalar(0.4, 0.4, 0.4));
  expect_empty(DensifyDepth(blank, v.NeighborPtrs(), DepthMap(90, 160), v.volume, o), 90, 160);
  // No depth on a textured frame, and no neighbours.
  expect_empty(DensifyDepth(v.ref, v.NeighborPtrs(), DepthMap(90, 160), v.volume, o), 90, 160);
  expect_empty(DensifyDepth(v.ref, {}, DepthMap(90, 160), v.volume, o), 90, 160);
  // A depth map of another size, or an empty frame.
  expect_empty(DensifyDepth(v.ref, v.NeighborPtrs(), DepthMap(10, 10), v.volume, o), 90, 160);
  ViewImage empty;
  empty.view = v.ref.view;
  const DepthMap from_empty = DensifyDepth(empty, v.NeighborPtrs(), DepthMap(), v.volume, o);
  EXPECT_TRUE(from_empty.depth.empty() || cv::countNonZero(from_empty.depth) == 0);

  // Confidence all zero: photoconsistency 0 everywhere (no neighbour sees the
  // pixels) and depth confidence 0: nothing to propagate, nothing invented.
  DepthMap sparse = GradientDepthEstimator(GradientDepthOptions()).Estimate(v.ref, v.NeighborPtrs(), v.volume);
  ASSERT_GT(sparse.CountValid(), 100);
  sparse.confidence = cv::Mat(sparse.depth.size(), CV_32F, cv::Scalar(1.0f));  // trust every depth here
  ASSERT_GT(DensifyDepth(v.ref, v.NeighborPtrs(), sparse, v.volume, o).CountValid(), sparse.CountValid());
  DepthMap zero_conf = sparse;
  zero_conf.confidence = cv::Mat(sparse.depth.size(), CV_32F, cv::Scalar(0.0f));  // a new buffer, not sparse's
  expect_empty(DensifyDepth(v.ref, v.NeighborPtrs(), zero_conf, v.volume, o), 90, 160);
  PropagationOptions paper = PaperPropagationOptions();  // C± alone: zero with no neighbour
  expect_empty(DensifyDepth(v.ref, {}, sparse, v.volume, paper), 90, 160);

  // All background: every depth labelled background gives background only.
  DepthMap all_bg = sparse;
  all_bg.label = cv::Mat(sparse.depth.size(), CV_8U, cv::Scalar(kBg));
  const DepthMap bg = DensifyDepth(v.ref, v.NeighborPtrs(), all_bg, v.volume, o);
  EXPECT_GT(bg.CountValid(), sparse.CountValid());
  EXPECT_EQ(cv::countNonZero(bg.label == kFg), 0);
  EXPECT_EQ(cv::countNonZero(bg.label == kBg), bg.CountValid());
  for (const DepthMap* m : {&bg}) {
    EXPECT_TRUE(cv::checkRange(m->depth));
    EXPECT_TRUE(cv::checkRange(m->confidence));
  }
  // Depths without labels are labelled from V: the sphere's are foreground.
  DepthMap unlabelled = sparse;
  unlabelled.label = cv::Mat();
  const DepthMap from_v = DensifyDepth(v.ref, v.NeighborPtrs(), unlabelled, v.volume, o);
  EXPECT_GT(cv::countNonZero(from_v.label == kFg), 1000);
}

TEST(DepthPropagator, DensifyDepthIsRunAndTheOptionsAreChecked) {
  const Fixture& f = Panel();
  const PropagationOptions o;
  const DepthMap a = DensifyDepth(f.v.ref, f.v.NeighborPtrs(), f.sparse, f.v.volume, o);
  const DepthMap b = DepthPropagator(o).Run(f.v.ref, f.v.NeighborPtrs(), f.sparse, f.v.volume).dense;
  EXPECT_EQ(cv::norm(a.depth, b.depth, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(a.label, b.label, cv::NORM_INF), 0.0);

  PropagationOptions bad;
  bad.dt_sigma_spatial = 0;
  EXPECT_THROW(DepthPropagator{bad}, OptionError);
  bad = PropagationOptions();
  bad.dt_sigma_color = -1;
  EXPECT_THROW(bad.Check(), OptionError);
  bad = PropagationOptions();
  bad.photo.sigma_p = 0;
  EXPECT_THROW(bad.Check(), OptionError);
  bad = PropagationOptions();
  bad.min_filtered_confidence = 1.0;
  EXPECT_THROW(bad.Check(), OptionError);
}

}  // namespace
}  // namespace lfrecon
