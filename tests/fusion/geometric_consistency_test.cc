#include "fusion/geometric_consistency.h"

#include <cstdio>

#include <gtest/gtest.h>

#include <cmath>

#include "fusion_test_rig.h"
#include "util/error.h"

namespace lfrecon {
namespace {

constexpr double kRadius = 0.1;  // a sphere at the origin, inside V

// Views 2° apart on an arc 0.6 m from the origin, looking at it.
std::vector<PinholeView> Arc(int n) {
  std::vector<PinholeView> views;
  for (int i = 0; i < n; ++i) {
    const double az = (i - n / 2) * 2.0 * M_PI / 180.0;
    views.push_back(testing::LookAtView({0.6 * std::cos(az), 0.6 * std::sin(az), 0.1}, Eigen::Vector3d::Zero(), 80,
                                        60, 50));
  }
  return views;
}

// Exact planar depth of the sphere (0 where the ray misses it), confidence 1, labels from V.
DepthMap SphereDepth(const PinholeView& v) {
  DepthMap m(v.height, v.width);
  const Eigen::Vector3d c = v.Center();
  for (int r = 0; r < v.height; ++r)
    for (int col = 0; col < v.width; ++col) {
      const Eigen::Vector3d u = v.RayDirection(Eigen::Vector2d(col + 0.5, r + 0.5));
      const double b = u.dot(c), disc = b * b - (c.squaredNorm() - kRadius * kRadius);
      if (disc < 0) continue;
      const double t = -b - std::sqrt(disc);
      m.depth.at<float>(r, col) = static_cast<float>(t * u.dot(v.ViewingDirection()));
      m.confidence.at<float>(r, col) = 1;
      m.label.at<std::uint8_t>(r, col) = static_cast<std::uint8_t>(DepthLabel::kForeground);
    }
  return m;
}

DepthMap Clone(const DepthMap& m) {
  DepthMap c;
  c.depth = m.depth.clone();
  c.confidence = m.confidence.clone();
  c.label = m.label.clone();
  return c;
}

struct Rig {
  std::vector<PinholeView> views = Arc(17);
  std::vector<DepthMap> maps;
  BoundingBox volume{Eigen::Vector3d::Constant(-0.2), Eigen::Vector3d::Constant(0.2)};
  Rig() {
    for (const PinholeView& v : views) maps.push_back(SphereDepth(v));
  }
  std::vector<NeighbourDepth> Neighbours(int k, const std::vector<int>& offsets) const {
    std::vector<NeighbourDepth> nb;
    for (int o : offsets)
      for (int s : {-1, 1}) nb.push_back({&views[k + s * o], &maps[k + s * o].depth});
    return nb;
  }
};

// A "halo": pixels beside the sphere's silhouette given a depth 5 cm in front
// of the sphere's centre (inside V, in empty space), as propagation does.
int AddHalo(const PinholeView& v, DepthMap* m, cv::Mat* where) {
  *where = cv::Mat::zeros(m->depth.size(), CV_8U);
  int n = 0;
  for (int r = 0; r < m->depth.rows; ++r)
    for (int c = 0; c < m->depth.cols; ++c) {
      if (m->depth.at<float>(r, c) > 0) continue;
      const double d = (v.Center().norm() - 0.05);
      const Eigen::Vector3d X = v.Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), d);
      if (X.norm() > 1.6 * kRadius) continue;  // a ring around the silhouette
      m->depth.at<float>(r, c) = static_cast<float>(d);
      m->confidence.at<float>(r, c) = 1;
      where->at<std::uint8_t>(r, c) = 1;
      ++n;
    }
  return n;
}

TEST(GeometricConsistency, KeepsASurfaceTheNeighboursSeeAndDropsAHaloTheyDoNot) {
  Rig rig;
  GeometricConsistencyOptions o;
  o.enabled = true;
  o.min_agree_fraction = 0;  // 4 of the 8 (the default, every neighbour, below)
  const int k = 8;
  DepthMap map = Clone(rig.maps[k]);
  cv::Mat halo;
  const int halo_pixels = AddHalo(rig.views[k], &map, &halo);
  ASSERT_GT(halo_pixels, 200);
  const int sphere_pixels = rig.maps[k].CountValid();
  ASSERT_GT(sphere_pixels, 500);
  const GeometricConsistencyStats st =
      ApplyGeometricConsistency(rig.views[k], cv::Mat(), rig.Neighbours(k, o.offsets), rig.volume, o, &map);
  EXPECT_EQ(st.foreground, sphere_pixels + halo_pixels);
  EXPECT_EQ(st.own, 0);
  int halo_left = 0, sphere_left = 0;
  for (int r = 0; r < map.depth.rows; ++r)
    for (int c = 0; c < map.depth.cols; ++c) {
      if (!(map.depth.at<float>(r, c) > 0)) {
        EXPECT_EQ(map.confidence.at<float>(r, c), 0.0f);
        EXPECT_EQ(map.label.at<std::uint8_t>(r, c), 0);
        continue;
      }
      (halo.at<std::uint8_t>(r, c) ? halo_left : sphere_left)++;
    }
  // The sphere's surface is seen by every neighbour (a few limb pixels land
  // on the background at the nearest pixel); the halo by none.
  EXPECT_GE(sphere_left, 0.97 * sphere_pixels);
  EXPECT_LE(halo_left, 0.01 * halo_pixels);
  EXPECT_EQ(st.dropped, sphere_pixels + halo_pixels - sphere_left - halo_left);

  // The default: every one of the 8 neighbours must agree. The halo goes as
  // well; of the sphere, the pixels whose point some neighbour sees at the
  // nearest pixel more than 1 % off (its limb, at this resolution) go too:
  // 490 of 640 kept, measured.
  DepthMap unanimous = Clone(rig.maps[k]);
  AddHalo(rig.views[k], &unanimous, &halo);
  const GeometricConsistencyStats su = ApplyGeometricConsistency(
      rig.views[k], cv::Mat(), rig.Neighbours(k, o.offsets), rig.volume, GeometricConsistencyOptions(), &unanimous);
  int kept_halo = 0, kept_sphere = 0;
  for (int r = 0; r < unanimous.depth.rows; ++r)
    for (int c = 0; c < unanimous.depth.cols; ++c)
      if (unanimous.depth.at<float>(r, c) > 0) (halo.at<std::uint8_t>(r, c) ? kept_halo : kept_sphere)++;
  std::printf("every neighbour: %d of %d sphere pixels kept, %d of %d halo pixels\n", kept_sphere, sphere_pixels,
              kept_halo, halo_pixels);
  EXPECT_EQ(kept_halo, 0);
  EXPECT_LE(kept_sphere, sphere_left);
  EXPECT_GE(kept_sphere, 0.7 * sphere_pixels);
  EXPECT_EQ(su.dropped, sphere_pixels + halo_pixels - kept_sphere);
}

TEST(GeometricConsistency, OwnDepthsAreNotCheckedAndTooFewNeighboursDropTheRest) {
  Rig rig;
  GeometricConsistencyOptions o;
  o.enabled = true;
  const int k = 8;
  DepthMap filtered = Clone(rig.maps[k]);
  DepthMap dense = Clone(rig.maps[k]);
  cv::Mat halo;
  const int halo_pixels = AddHalo(rig.views[k], &dense, &halo);
  // The halo's depths are the view's own (its filtered map has them): kept.
  AddHalo(rig.views[k], &filtered, &halo);
  cv::Mat own = OwnDepthMask(dense, filtered, o.own_tolerance);
  EXPECT_EQ(cv::countNonZero(own), dense.CountValid());
  DepthMap checked = Clone(dense);
  GeometricConsistencyStats st =
      ApplyGeometricConsistency(rig.views[k], own, rig.Neighbours(k, o.offsets), rig.volume, o, &checked);
  EXPECT_EQ(st.own, st.foreground);
  EXPECT_EQ(st.dropped, 0);
  EXPECT_EQ(cv::countNonZero(checked.depth != dense.depth), 0);
  // A filtered depth 2 % off is not the dense depth's own at 1 %.
  filtered.depth *= 1.02;
  own = OwnDepthMask(dense, filtered, o.own_tolerance);
  EXPECT_EQ(cv::countNonZero(own), 0);
  // Two neighbours cannot give four agreements: every checked depth goes.
  checked = Clone(dense);
  st = ApplyGeometricConsistency(rig.views[k], own, rig.Neighbours(k, {1}), rig.volume, o, &checked);
  EXPECT_EQ(st.dropped, st.foreground);
  EXPECT_EQ(st.foreground, rig.maps[k].CountValid() + halo_pixels);
  EXPECT_EQ(checked.CountValid(), 0);
}

TEST(GeometricConsistency, OptionsAreChecked) {
  GeometricConsistencyOptions o;
  EXPECT_NO_THROW(o.Check());
  EXPECT_EQ(o.Delay(), 8);  // on by default
  o.enabled = false;
  EXPECT_EQ(o.Delay(), 0);
  o.enabled = true;
  // Neighbour positions: the view's ± each offset, inside the list, nearest first.
  EXPECT_EQ(NeighbourPositions(4, 10, o), (std::vector<int>{3, 5, 2, 6, 0, 8}));
  EXPECT_EQ(NeighbourPositions(0, 3, o), (std::vector<int>{1, 2}));
  o.min_agree = 9;
  EXPECT_THROW(o.Check(), OptionError);
  o.min_agree = 4;
  o.offsets = {0};
  EXPECT_THROW(o.Check(), OptionError);
}

}  // namespace
}  // namespace lfrecon
