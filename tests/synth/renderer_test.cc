#include "synth/renderer.h"

#include <gtest/gtest.h>
#include <tbb/global_control.h>

#include <cmath>
#include <opencv2/imgproc.hpp>

#include "synth/scenes.h"
#include "synth/sequence.h"

namespace lfrecon::synth {
namespace {

using Eigen::Vector2d;
using Eigen::Vector3d;

PinholeView MakeView(int w, int h, double hfov, const Vector3d& eye, const Vector3d& target) {
  return PinholeView(Camera::PinholeFromHfov(w, h, hfov), LookAt(eye, target, Vector3d::UnitZ()));
}

// Luminance gradient magnitude by central differences (0 on the border).
cv::Mat GradientMagnitude(const cv::Mat& bgr) {
  cv::Mat gray;
  cv::cvtColor(bgr, gray, cv::COLOR_BGR2GRAY);
  cv::Mat mag(gray.size(), CV_32F, cv::Scalar(0));
  for (int r = 1; r + 1 < gray.rows; ++r)
    for (int c = 1; c + 1 < gray.cols; ++c) {
      const float gx = 0.5f * (gray.at<float>(r, c + 1) - gray.at<float>(r, c - 1));
      const float gy = 0.5f * (gray.at<float>(r + 1, c) - gray.at<float>(r - 1, c));
      mag.at<float>(r, c) = std::sqrt(gx * gx + gy * gy);
    }
  return mag;
}

// True if every pixel-centre label in the (2k+1)^2 window around (r, c) is `id`.
bool WindowIs(const cv::Mat& labels, int r, int c, int k, int id) {
  if (r < k || c < k || r + k >= labels.rows || c + k >= labels.cols) return false;
  for (int dr = -k; dr <= k; ++dr)
    for (int dc = -k; dc <= k; ++dc)
      if (labels.at<int>(r + dr, c + dc) != id) return false;
  return true;
}

TEST(Render, SphereDepthIsAnalyticAndLabelsMatch) {
  Scene scene("one_sphere");
  const Vector3d centre(0.05, -0.02, 0.3);
  const double radius = 0.12;
  scene.Add(Primitive::Sphere(centre, radius, Material::Noise({0.2f, 0.2f, 0.2f}, {0.8f, 0.8f, 0.8f}, 0.02)));
  const PinholeView view = MakeView(320, 180, 55, Vector3d(0.8, 0.5, 0.6), Vector3d(0, 0, 0.3));
  RenderOptions options;
  options.noise_sigma = 0;
  const RenderResult r = Render(scene, view, options, 1);
  ASSERT_EQ(r.depth.type(), CV_64F);
  ASSERT_EQ(r.labels.type(), CV_32S);

  // Independent solution in the camera frame: ray s * (x, y, 1), planar depth s.
  const Vector3d C = view.R * centre + view.t;
  int hits = 0, misses = 0, checked = 0;
  double worst = 0;
  for (int row = 0; row < view.height; ++row)
    for (int col = 0; col < view.width; ++col) {
      const Vector3d d((col + 0.5 - view.K(0, 2)) / view.K(0, 0), (row + 0.5 - view.K(1, 2)) / view.K(1, 1),
                       1.0);
      const double a = d.squaredNorm(), b = d.dot(C), c = C.squaredNorm() - radius * radius;
      const double disc = b * b - a * c;
      if (std::abs(disc) < 1e-9 * b * b) continue;  // grazing: either answer is right
      ++checked;
      if (disc < 0) {
        ++misses;
        EXPECT_EQ(r.labels.at<int>(row, col), -1);
        EXPECT_EQ(r.depth.at<double>(row, col), 0.0);
        continue;
      }
      ++hits;
      const double s = (b - std::sqrt(disc)) / a;
      ASSERT_EQ(r.labels.at<int>(row, col), 0) << row << "," << col;
      worst = std::max(worst, std::abs(r.depth.at<double>(row, col) - s) / s);
      // The unprojected point lies on the sphere.
      const Vector3d X = view.Unproject(Vector2d(col + 0.5, row + 0.5), r.depth.at<double>(row, col));
      EXPECT_NEAR((X - centre).norm(), radius, 1e-9 * radius);
    }
  EXPECT_LT(worst, 1e-9);
  EXPECT_GT(hits, 2000);
  EXPECT_GT(misses, 2000);
  EXPECT_GT(checked, view.width * view.height - 200);
}

TEST(Render, NothingHitGivesZeroDepthAndBackground) {
  Scene scene("empty");
  scene.set_background_color({0.25f, 0.5f, 0.75f});
  const PinholeView view = MakeView(64, 36, 55, Vector3d(1, 0, 0), Vector3d::Zero());
  RenderOptions options;
  options.noise_sigma = 0;
  const RenderResult r = Render(scene, view, options, 1);
  EXPECT_EQ(cv::countNonZero(r.depth), 0);
  EXPECT_EQ(cv::countNonZero(r.labels + 1), 0);
  const cv::Vec3f px = r.image.at<cv::Vec3f>(10, 10);
  EXPECT_FLOAT_EQ(px[0], 0.75f);  // BGR
  EXPECT_FLOAT_EQ(px[2], 0.25f);
}

// Tile culling must not change anything: every pixel centre of a full render
// equals a lone ray cast against all primitives.
TEST(Render, TileCullingMatchesBruteForceRays) {
  SynthOptions o;
  o.scene = "tabletop";
  o.frames = 24;
  o.width = 256;
  o.height = 144;
  o.path = PathType::kHandheld;
  const SynthSequence seq = SynthSequence::Create(o);
  for (int i : {0, 7, 15}) {
    const RenderResult r = seq.Render(i);
    const PinholeView view = seq.View(i);
    int mismatches = 0;
    for (int row = 0; row < view.height; ++row)
      for (int col = 0; col < view.width; ++col) {
        const Hit h = CastPixel(seq.scene(), view, Vector2d(col + 0.5, row + 0.5));
        if (h.id != r.labels.at<int>(row, col) || (h.ok() ? h.t : 0.0) != r.depth.at<double>(row, col))
          ++mismatches;
      }
    EXPECT_EQ(mismatches, 0) << "frame " << i;
  }
}

// View i's depth, moved into view j, agrees with what view j sees there.
TEST(Render, DepthReprojectsConsistentlyBetweenViews) {
  SynthOptions o;
  o.scene = "tabletop";
  o.frames = 480;  // 0.75 degrees per frame
  o.width = 320;
  o.height = 180;
  o.path = PathType::kHandheld;
  const SynthSequence seq = SynthSequence::Create(o);
  for (auto [i, j] : {std::pair{10, 14}, std::pair{200, 193}}) {
    const RenderResult ri = seq.Render(i);
    const PinholeView vi = seq.View(i), vj = seq.View(j);
    int covisible = 0, agree = 0, in_view = 0;
    for (int row = 0; row < vi.height; ++row)
      for (int col = 0; col < vi.width; ++col) {
        const double d = ri.depth.at<double>(row, col);
        if (d <= 0 || ri.mixed.at<std::uint8_t>(row, col)) continue;  // skip silhouettes / occlusion edges
        const Vector3d X = vi.Unproject(Vector2d(col + 0.5, row + 0.5), d);
        Vector2d q;
        const double zj = vj.Project(X, &q);
        if (zj <= 0 || !vj.InImage(q)) continue;
        ++in_view;
        const Hit h = CastPixel(seq.scene(), vj, q);
        if (h.id != ri.labels.at<int>(row, col)) continue;  // occluded in j by something else
        ++covisible;
        if (std::abs(h.t - zj) <= 1e-6 * zj) ++agree;
      }
    EXPECT_GT(covisible, 0.9 * in_view) << i << "->" << j;
    EXPECT_GE(agree, 0.99 * covisible) << i << "->" << j;
  }
}

// Map to map: on a plane inverse depth is affine in the pixel coordinates, so
// bilinear interpolation of view j's inverse depth is exact there.
TEST(Render, PlaneDepthMapsAgreeMapToMap) {
  SynthOptions o;
  o.scene = "plane";
  o.frames = 120;
  o.width = 320;
  o.height = 180;
  const SynthSequence seq = SynthSequence::Create(o);
  const int plane_id = 0;
  ASSERT_EQ(seq.scene().primitive(plane_id).name, "plane");
  const RenderResult ri = seq.Render(60), rj = seq.Render(66);
  const PinholeView vi = seq.View(60), vj = seq.View(66);
  int tested = 0, agree = 0;
  for (int row = 0; row < vi.height; ++row)
    for (int col = 0; col < vi.width; ++col) {
      if (ri.labels.at<int>(row, col) != plane_id) continue;
      const double d = ri.depth.at<double>(row, col);
      Vector2d q;
      const double zj = vj.Project(vi.Unproject(Vector2d(col + 0.5, row + 0.5), d), &q);
      const double x = q.x() - 0.5, y = q.y() - 0.5;  // pixel-centre grid coordinates
      const int c0 = static_cast<int>(std::floor(x)), r0 = static_cast<int>(std::floor(y));
      if (c0 < 0 || r0 < 0 || c0 + 1 >= vj.width || r0 + 1 >= vj.height) continue;
      bool ok = true;
      for (int k = 0; k < 4; ++k) ok = ok && rj.labels.at<int>(r0 + k / 2, c0 + k % 2) == plane_id;
      if (!ok) continue;
      const double fx = x - c0, fy = y - r0;
      auto inv = [&](int r, int c) { return 1.0 / rj.depth.at<double>(r, c); };
      const double inv_d = (1 - fy) * ((1 - fx) * inv(r0, c0) + fx * inv(r0, c0 + 1)) +
                           fy * ((1 - fx) * inv(r0 + 1, c0) + fx * inv(r0 + 1, c0 + 1));
      ++tested;
      if (std::abs(1.0 / inv_d - zj) <= 1e-6 * zj) ++agree;
    }
  EXPECT_GT(tested, vi.width * vi.height / 2);
  EXPECT_EQ(agree, tested);
}

TEST(Render, DeterministicAcrossRunsThreadsAndSeeds) {
  SynthOptions o;
  o.scene = "occlusion";
  o.frames = 10;
  o.width = 160;
  o.height = 90;
  const SynthSequence a = SynthSequence::Create(o);
  const RenderResult r1 = a.Render(3);
  const RenderResult r2 = a.Render(3);
  EXPECT_EQ(cv::norm(r1.image, r2.image, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(r1.depth, r2.depth, cv::NORM_INF), 0.0);
  {
    tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
    const RenderResult r3 = a.Render(3);
    EXPECT_EQ(cv::norm(r1.image, r3.image, cv::NORM_INF), 0.0);
  }
  // Same seed, another frame: new noise. Another seed: other textures and noise.
  o.seed = 2;
  const SynthSequence b = SynthSequence::Create(o);
  const RenderResult rb = b.Render(3);
  EXPECT_EQ(cv::norm(r1.depth, rb.depth, cv::NORM_INF), 0.0);  // geometry and poses are the same
  EXPECT_GT(cv::norm(r1.image, rb.image, cv::NORM_L1) / (3.0 * r1.image.total()), 0.02);
}

TEST(Render, NoiseHasTheRequestedSigma) {
  SynthOptions o;
  o.scene = "sphere";
  o.frames = 4;
  o.width = 160;
  o.height = 90;
  o.render.noise_sigma = 0;
  const SynthSequence clean = SynthSequence::Create(o);
  o.render.noise_sigma = 0.01;
  const SynthSequence noisy = SynthSequence::Create(o);
  cv::Mat diff = noisy.Render(1).image - clean.Render(1).image;
  cv::Scalar mean, stddev;
  cv::meanStdDev(diff.reshape(1), mean, stddev);
  EXPECT_NEAR(stddev[0], 0.01, 0.001);
  EXPECT_NEAR(mean[0], 0.0, 0.001);
  // Noise differs between frames of one sequence.
  cv::Mat d2 = noisy.Render(2).image - clean.Render(2).image;
  EXPECT_GT(cv::norm(diff, d2, cv::NORM_INF), 0.01);
}

TEST(Render, QuantizeGivesEightBitLevels) {
  SynthOptions o;
  o.scene = "sphere";
  o.frames = 2;
  o.width = 64;
  o.height = 36;
  o.render.quantize = true;
  const cv::Mat img = SynthSequence::Create(o).Render(0).image;
  cv::Mat scaled = img * 255.0, rounded;
  scaled.convertTo(rounded, CV_8UC3);
  rounded.convertTo(rounded, CV_32FC3);
  EXPECT_LT(cv::norm(scaled, rounded, cv::NORM_INF), 1e-3);
}

// The fast path (one filtered texture sample for pixels inside a surface) stays
// close to box-filtering all samples; silhouette pixels are computed the same way.
TEST(Render, AdaptiveSamplingMatchesFullSupersampling) {
  SynthOptions o;
  o.scene = "tabletop";
  o.frames = 8;
  o.width = 320;
  o.height = 180;
  o.render.noise_sigma = 0;
  const SynthSequence fast = SynthSequence::Create(o);
  o.render.adaptive = false;
  const SynthSequence full = SynthSequence::Create(o);
  const RenderResult a = fast.Render(2), b = full.Render(2);
  EXPECT_EQ(cv::norm(a.depth, b.depth, cv::NORM_INF), 0.0);
  EXPECT_EQ(cv::norm(a.labels, b.labels, cv::NORM_INF), 0.0);
  cv::Mat diff;
  cv::absdiff(a.image, b.image, diff);
  double interior_sum = 0;
  int interior = 0, mixed = 0;
  for (int r = 0; r < diff.rows; ++r)
    for (int c = 0; c < diff.cols; ++c) {
      const cv::Vec3f d = diff.at<cv::Vec3f>(r, c);
      if (a.mixed.at<std::uint8_t>(r, c)) {
        ++mixed;
        EXPECT_EQ(d[0] + d[1] + d[2], 0.0f);
      } else {
        interior_sum += (d[0] + d[1] + d[2]) / 3;
        ++interior;
      }
    }
  EXPECT_GT(mixed, 200);
  EXPECT_LT(interior_sum / interior, 0.01);
}

// Textured surfaces give the gradients the depth method needs (||grad I|| > 0.05).
TEST(Render, TexturedPrimitivesHaveStrongGradients) {
  SynthOptions o;
  o.scene = "tabletop";
  o.frames = 8;
  o.width = 640;
  o.height = 360;
  const SynthSequence seq = SynthSequence::Create(o);
  for (int i : {0, 3}) {
    const RenderResult r = seq.Render(i);
    const cv::Mat mag = GradientMagnitude(r.image);
    for (const char* name : {"sphere", "box", "cup", "stool_top", "floor", "table"}) {
      int id = -1;
      for (int k = 0; k < seq.scene().NumPrimitives(); ++k)
        if (seq.scene().primitive(k).name == name) id = k;
      if (id < 0) continue;
      int n = 0, strong = 0;
      for (int row = 0; row < mag.rows; ++row)
        for (int col = 0; col < mag.cols; ++col)
          if (WindowIs(r.labels, row, col, 2, id)) {
            ++n;
            if (mag.at<float>(row, col) > 0.05f) ++strong;
          }
      if (n < 200) continue;
      const double share = static_cast<double>(strong) / n;
      RecordProperty(std::string("strong_gradient_share_") + name, std::to_string(share));
      EXPECT_GT(share, 0.5) << name << " frame " << i << " (" << n << " interior pixels)";
    }
  }
}

// The textureless thin cylinder has gradients only at its silhouette.
TEST(Render, TexturelessThinCylinderHasNoInteriorGradient) {
  // Default rig: the cylinder is 2-3 px wide.
  SynthOptions o;
  o.scene = "thin_cylinder";
  o.frames = 8;
  const SynthSequence seq = SynthSequence::Create(o);
  const RenderResult r = seq.Render(2);
  const cv::Mat mag = GradientMagnitude(r.image);
  std::vector<int> widths;
  int silhouette = 0, silhouette_strong = 0;
  for (int row = 0; row < r.labels.rows; ++row) {
    int w = 0;
    for (int col = 1; col + 1 < r.labels.cols; ++col) {
      if (r.labels.at<int>(row, col) != 0) continue;
      ++w;
      ++silhouette;  // at 2-3 px wide every cylinder pixel touches the silhouette
      if (mag.at<float>(row, col) > 0.05f) ++silhouette_strong;
    }
    if (w > 0) widths.push_back(w);
  }
  ASSERT_GT(widths.size(), 100u);
  std::nth_element(widths.begin(), widths.begin() + widths.size() / 2, widths.end());
  const int median = widths[widths.size() / 2];
  EXPECT_GE(median, 2);
  EXPECT_LE(median, 3);
  EXPECT_GT(silhouette_strong, 0.8 * silhouette);

  // Zoomed in (hfov 12 degrees: about 10 px wide), interior pixels are flat.
  for (double sigma : {0.0, 0.01}) {
    o.hfov_deg = 12;
    o.render.noise_sigma = sigma;
    const SynthSequence zoom = SynthSequence::Create(o);
    const RenderResult z = zoom.Render(2);
    const cv::Mat m = GradientMagnitude(z.image);
    int interior = 0, strong = 0;
    float worst = 0;
    for (int row = 0; row < m.rows; ++row)
      for (int col = 0; col < m.cols; ++col)
        if (WindowIs(z.labels, row, col, 2, 0)) {
          ++interior;
          worst = std::max(worst, m.at<float>(row, col));
          if (m.at<float>(row, col) > 0.05f) ++strong;
        }
    ASSERT_GT(interior, 500) << "sigma " << sigma;
    EXPECT_EQ(strong, 0) << "sigma " << sigma;
    if (sigma == 0) {
      EXPECT_LT(worst, 1e-6f);
    }
  }
}

TEST(Render, LabelsFollowForegroundAndThinFlags) {
  SynthOptions o;
  o.scene = "tabletop";
  o.frames = 8;
  o.width = 320;
  o.height = 180;
  const SynthSequence seq = SynthSequence::Create(o);
  const RenderResult r = seq.Render(1);
  const cv::Mat fg = ForegroundMask(seq.scene(), r.labels), thin = ThinMask(seq.scene(), r.labels);
  const PinholeView view = seq.View(1);
  const BoundingBox& V = seq.scene().foreground_bbox();
  int n_fg = 0, n_thin = 0, wrong = 0;
  for (int row = 0; row < r.labels.rows; ++row)
    for (int col = 0; col < r.labels.cols; ++col) {
      const double d = r.depth.at<double>(row, col);
      if (d <= 0) continue;
      // Foreground label <=> the pixel's 3D point lies in V (the method's definition).
      const bool in_v = V.Contains(view.Unproject(Vector2d(col + 0.5, row + 0.5), d));
      const bool is_fg = fg.at<std::uint8_t>(row, col) != 0;
      if (in_v != is_fg) ++wrong;
      n_fg += is_fg;
      n_thin += thin.at<std::uint8_t>(row, col) != 0;
      if (thin.at<std::uint8_t>(row, col)) {
        EXPECT_TRUE(is_fg);
      }
    }
  EXPECT_EQ(wrong, 0);
  EXPECT_GT(n_fg, 2000);
  EXPECT_GT(n_thin, 50);
}

}  // namespace
}  // namespace lfrecon::synth
