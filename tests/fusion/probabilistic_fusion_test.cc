// Fusion of exact synthetic depth maps: accuracy of the H = 0.2 surface,
// order independence, free-space carving, thin features.
#include "fusion/probabilistic_fusion.h"

#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <filesystem>
#include <map>
#include <random>

#include "eval/mesh_metrics.h"
#include "fusion/surface_evidence.h"
#include "fusion_test_rig.h"
#include "synth/gt_mesh.h"
#include "util/error.h"
#include "util/progress.h"

namespace lfrecon {
namespace {

using testing::Box;
using testing::ExactDepth;

struct Rendered {
  std::vector<PinholeView> views;
  std::vector<DepthMap> depths;
};

Rendered RenderAll(const synth::Scene& scene, const std::vector<PinholeView>& views) {
  Rendered r;
  r.views = views;
  for (const PinholeView& v : views) r.depths.push_back(ExactDepth(scene, v));
  return r;
}

ProbabilisticFusion Fuse(const FusionOptions& options, const Rendered& data, const std::vector<int>& order = {}) {
  ProbabilisticFusion fusion(options);
  for (std::size_t k = 0; k < data.views.size(); ++k) {
    const std::size_t i = order.empty() ? k : static_cast<std::size_t>(order[k]);
    fusion.Integrate(data.views[i], data.depths[i]);
  }
  return fusion;
}

MeshMetrics Score(const TriangleMesh& mesh, const TriangleMesh& gt, const TriangleMesh* thin, double tau,
                  const BoundingBox& volume) {
  MeshMetricsOptions mo;
  mo.thresholds = {tau};
  mo.sample_spacing = tau / 4;
  mo.volume = volume;
  return EvaluateMesh(mesh, gt, thin, mo);
}

// Every directed edge once and its reverse once: closed and consistently oriented.
int CountBadEdges(const TriangleMesh& mesh) {
  std::map<std::pair<int, int>, int> directed;
  for (const Eigen::Vector3i& t : mesh.triangles)
    for (int k = 0; k < 3; ++k) directed[{t[k], t[(k + 1) % 3]}]++;
  int bad = 0;
  for (const auto& [e, n] : directed) {
    const auto rev = directed.find({e.second, e.first});
    if (n != 1 || rev == directed.end() || rev->second != 1) ++bad;
  }
  return bad;
}

synth::Scene SphereScene() {
  synth::Scene s("sphere");
  s.set_foreground_bbox(Box(Eigen::Vector3d::Constant(-0.14), Eigen::Vector3d::Constant(0.14)));
  s.Add(synth::Primitive::Sphere(Eigen::Vector3d::Zero(), 0.1, synth::Material::Flat({0.9f, 0.3f, 0.1f}))
            .Named("sphere")
            .Foreground());
  testing::AddDome(&s);
  return s;
}

synth::Scene BoxScene() {
  synth::Scene s("box");
  s.set_foreground_bbox(Box(Eigen::Vector3d::Constant(-0.14), Eigen::Vector3d::Constant(0.14)));
  const Eigen::Matrix3d R = (Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()) *
                             Eigen::AngleAxisd(0.2, Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  s.Add(synth::Primitive::Box({0.01, -0.005, 0.0}, {0.08, 0.05, 0.06}, synth::Material::Flat({0.2f, 0.5f, 0.9f}), R)
            .Named("box")
            .Foreground());
  testing::AddDome(&s);
  return s;
}

FusionOptions OptionsFor(const synth::Scene& scene, double voxel) {
  FusionOptions o;
  o.volume = scene.foreground_bbox();
  o.voxel_size = voxel;
  return o;
}

class FusionAccuracy : public ::testing::TestWithParam<const char*> {};

TEST_P(FusionAccuracy, ExactDepthGivesF1AboveNinetyFivePercentAtOneVoxel) {
  const std::string name = GetParam();
  const synth::Scene scene = name == "sphere" ? SphereScene() : BoxScene();
  const double voxel = 0.004;
  const Rendered data = RenderAll(scene, testing::SphereRig(40, Eigen::Vector3d::Zero(), 0.6, 160, 90, 40));
  Timer timer;
  const ProbabilisticFusion fusion = Fuse(OptionsFor(scene, voxel), data);
  const double fuse_s = timer.Seconds();
  const TriangleMesh mesh = fusion.ExtractMesh();
  const MeshMetrics m = Score(mesh, synth::GroundTruthMesh(scene), nullptr, voxel, scene.foreground_bbox());
  const MeshMetrics half = Score(mesh, synth::GroundTruthMesh(scene), nullptr, voxel / 2, scene.foreground_bbox());
  const FusionStats st = fusion.Stats();
  std::printf("%s: %zu active voxels (%.1f%% of V), %zu triangles, fused in %.2f s; F %.4f at %.0f mm, %.4f at %.0f mm\n",
              name.c_str(), st.active_voxels, 100.0 * st.active_voxels / OptionsFor(scene, voxel).GridSize().prod(),
              mesh.triangles.size(), fuse_s, m.scores[0].fscore, voxel * 1000, half.scores[0].fscore, voxel * 500);
  EXPECT_GE(m.scores[0].fscore, 0.95);
  // Exact depth puts the surface well within half a voxel (0.99 measured with the defaults).
  EXPECT_GE(half.scores[0].fscore, 0.95);
  EXPECT_EQ(CountBadEdges(mesh), 0) << "the mesh of a closed object must be closed and consistently oriented";
  // Normals point outward: away from the object's centre.
  double mean_dot = 0;
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i)
    mean_dot += mesh.normals[i].dot(mesh.vertices[i].normalized());
  EXPECT_GT(mean_dot / mesh.vertices.size(), 0.7);
  // Memory follows the surface: the band is a thin shell, far from all of V.
  EXPECT_LT(st.active_voxels, OptionsFor(scene, voxel).GridSize().prod() / 4);
}

INSTANTIATE_TEST_SUITE_P(Shapes, FusionAccuracy, ::testing::Values("sphere", "box"));

TEST(ProbabilisticFusion, PruningKeepsTheSurfaceAndItsValues) {
  // Pruning drops voxels far below the threshold; what stays must hold the
  // same H as without pruning, and the mesh must not change in substance.
  const synth::Scene scene = BoxScene();
  const Rendered data = RenderAll(scene, testing::SphereRig(40, Eigen::Vector3d::Zero(), 0.6, 160, 90, 40));
  FusionOptions options = OptionsFor(scene, 0.004);
  const ProbabilisticFusion full = Fuse(options, data);
  options.prune_every = 4;
  const ProbabilisticFusion pruned = Fuse(options, data);
  const FusionStats sf = full.Stats(), sp = pruned.Stats();
  std::printf("pruning: %zu active voxels without, %zu with (%zu dropped over the run)\n", sf.active_voxels,
              sp.active_voxels, sp.pruned_voxels);
  EXPECT_GT(sp.pruned_voxels, 0u);
  EXPECT_LT(sp.active_voxels, sf.active_voxels);
  double max_diff = 0;
  int missing_above = 0;
  pruned.ForEachVoxel([&](const Eigen::Vector3i& v, double sum, int n) {
    int nf = 0;
    const double hf = full.SurfaceProbability(v, &nf);
    max_diff = std::max(max_diff, std::abs((n > 0 ? std::exp(sum / n) : 0.0) - hf));
  });
  full.ForEachVoxel([&](const Eigen::Vector3i& v, double sum, int n) {
    if (n > 0 && std::exp(sum / n) >= options.surface_threshold && !pruned.IsActive(v)) ++missing_above;
  });
  EXPECT_LE(max_diff, 1e-5);
  EXPECT_EQ(missing_above, 0) << "a voxel above the threshold was pruned";
  const MeshMetrics mf = Score(full.ExtractMesh(), synth::GroundTruthMesh(scene), nullptr, 0.004, scene.foreground_bbox());
  const MeshMetrics mp = Score(pruned.ExtractMesh(), synth::GroundTruthMesh(scene), nullptr, 0.004, scene.foreground_bbox());
  EXPECT_NEAR(mp.scores[0].fscore, mf.scores[0].fscore, 0.002);
}

TEST(ProbabilisticFusion, WeakDepthsDoNotActivateVoxels) {
  // A view whose depths are all weak (c = 0.02) and displaced 3 cm towards the
  // camera: with activation_min_confidence it adds no voxels of its own, and
  // the confident views' voxels keep exactly the H they would have had.
  const synth::Scene scene = BoxScene();
  Rendered data = RenderAll(scene, testing::SphereRig(24, Eigen::Vector3d::Zero(), 0.6, 160, 90, 40));
  DepthMap weak;
  weak.depth = data.depths[0].depth.clone();
  if (!data.depths[0].label.empty()) weak.label = data.depths[0].label.clone();
  weak.confidence = cv::Mat(weak.depth.size(), CV_32F, cv::Scalar(0.02f));
  cv::Mat shifted = weak.depth - 0.03;
  shifted.copyTo(weak.depth, weak.depth > 0.05);
  FusionOptions options = OptionsFor(scene, 0.004);
  options.activation_min_confidence = 0.05;
  const ProbabilisticFusion confident_only = Fuse(options, data);
  data.views.push_back(data.views[0]);
  data.depths.push_back(weak);
  const ProbabilisticFusion with_weak = Fuse(options, data);
  options.activation_min_confidence = 0;
  const ProbabilisticFusion unfiltered = Fuse(options, data);
  EXPECT_EQ(with_weak.Stats().active_voxels, confident_only.Stats().active_voxels);
  EXPECT_GT(unfiltered.Stats().active_voxels, with_weak.Stats().active_voxels + 1000);
  double max_diff = 0;
  with_weak.ForEachVoxel([&](const Eigen::Vector3i& v, double sum, int n) {
    max_diff = std::max(max_diff, std::abs(std::exp(sum / n) - unfiltered.SurfaceProbability(v)));
  });
  EXPECT_LE(max_diff, 1e-5);
}

TEST(ProbabilisticFusion, OrderIndependent) {
  const synth::Scene scene = BoxScene();
  const Rendered data = RenderAll(scene, testing::SphereRig(24, Eigen::Vector3d::Zero(), 0.6, 160, 90, 40));
  const FusionOptions options = OptionsFor(scene, 0.004);
  std::vector<int> order(data.views.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = static_cast<int>(i);
  std::vector<int> shuffled = order;
  std::mt19937 rng(7);
  std::shuffle(shuffled.begin(), shuffled.end(), rng);
  std::vector<int> reversed(order.rbegin(), order.rend());

  const ProbabilisticFusion a = Fuse(options, data, order);
  std::map<std::tuple<int, int, int>, std::pair<double, int>> ha;
  a.ForEachVoxel([&](const Eigen::Vector3i& v, double sum, int n) {
    ha[{v.x(), v.y(), v.z()}] = {n > 0 ? std::exp(sum / n) : 0.0, n};
  });
  ASSERT_GT(ha.size(), 1000u);
  for (const auto& other_order : {shuffled, reversed}) {
    const ProbabilisticFusion b = Fuse(options, data, other_order);
    std::size_t count = 0;
    double max_diff = 0;
    int count_mismatch = 0;
    b.ForEachVoxel([&](const Eigen::Vector3i& v, double sum, int n) {
      ++count;
      const auto it = ha.find({v.x(), v.y(), v.z()});
      ASSERT_NE(it, ha.end());
      max_diff = std::max(max_diff, std::abs((n > 0 ? std::exp(sum / n) : 0.0) - it->second.first));
      count_mismatch += n != it->second.second;
    });
    std::printf("order: %zu voxels, max |ΔH| = %.3g\n", count, max_diff);
    EXPECT_EQ(count, ha.size());
    EXPECT_EQ(count_mismatch, 0);
    EXPECT_LE(max_diff, 1e-5);
  }
  // A re-issued view (same id) is ignored instead of counted twice.
  {
    ProbabilisticFusion c(options);
    EXPECT_TRUE(c.Integrate(data.views[0], data.depths[0], 0));
    const std::size_t active = c.Stats().active_voxels;
    EXPECT_FALSE(c.Integrate(data.views[0], data.depths[0], 0));
    EXPECT_EQ(c.NumViews(), 1);
    EXPECT_EQ(c.Stats().active_voxels, active);
    EXPECT_TRUE(c.HasView(0));
  }
  // Half-way, H is already readable and most active voxels have evidence.
  ProbabilisticFusion half(options);
  for (int i = 0; i < 12; ++i) half.Integrate(data.views[i], data.depths[i]);
  // Voxels activated at grazing angles may still lack evidence (their centre
  // projects onto a nearer neighbouring pixel, so they are occluded there).
  std::size_t empty = 0, total = 0;
  half.ForEachVoxel([&](const Eigen::Vector3i&, double, int n) {
    empty += n == 0;
    ++total;
  });
  EXPECT_LT(empty, total / 10);
  EXPECT_GT(half.ExtractMesh().triangles.size(), 0u);
}

// H of every active voxel of `a`, compared with `b`: the largest and mean
// |ΔH|, and how many voxels are on different sides of the threshold.
struct HDiff {
  double max = 0, mean = 0;
  std::size_t voxels = 0, flipped = 0, missing = 0;
};
HDiff CompareH(const ProbabilisticFusion& a, const ProbabilisticFusion& b, double threshold) {
  HDiff d;
  a.ForEachVoxel([&](const Eigen::Vector3i& v, double sum, int n) {
    const double ha = n > 0 ? std::exp(sum / n) : 0.0;
    if (!b.IsActive(v)) ++d.missing;
    const double hb = b.SurfaceProbability(v);
    d.max = std::max(d.max, std::abs(ha - hb));
    d.mean += std::abs(ha - hb);
    d.flipped += (ha >= threshold) != (hb >= threshold);
    ++d.voxels;
  });
  if (d.voxels > 0) d.mean /= d.voxels;
  return d;
}

TEST(ProbabilisticFusion, StoreBudgetBoundsMemoryAndKeepsTheSurface) {
  // 40 views of 160x90 (57.6 KB each stored exactly, 2.3 MB in all) under a
  // 300 KB budget: most views end at 4x4 blocks (11 mm at the box, 4 mm voxels).
  const synth::Scene scene = BoxScene();
  const Rendered data = RenderAll(scene, testing::SphereRig(40, Eigen::Vector3d::Zero(), 0.6, 160, 90, 40));
  FusionOptions options = OptionsFor(scene, 0.004);
  options.store_budget_bytes = 0;
  const ProbabilisticFusion exact = Fuse(options, data);
  options.store_budget_bytes = 300 * 1000;
  const ProbabilisticFusion budget = Fuse(options, data);
  const FusionStats se = exact.Stats(), sb = budget.Stats();
  EXPECT_EQ(se.store_coarsened_views, 0);
  EXPECT_GT(se.store_bytes, 2000u * 1000u);
  EXPECT_LE(sb.store_bytes, options.store_budget_bytes);
  EXPECT_GE(sb.store_max_block, 4);
  EXPECT_EQ(sb.active_voxels, se.active_voxels) << "activation never reads the store";
  const HDiff d = CompareH(exact, budget, options.surface_threshold);
  const TriangleMesh gt = synth::GroundTruthMesh(scene);
  const double fe = Score(exact.ExtractMesh(), gt, nullptr, 0.004, scene.foreground_bbox()).scores[0].fscore;
  const double fb = Score(budget.ExtractMesh(), gt, nullptr, 0.004, scene.foreground_bbox()).scores[0].fscore;
  std::printf("budget: store %zu -> %zu bytes (%d views coarsened, blocks up to %d), %zu voxels: max |dH| %.3f, "
              "mean %.4f, %zu flipped at the threshold; F@4mm %.4f exact, %.4f with the budget\n",
              se.store_bytes, sb.store_bytes, sb.store_coarsened_views, sb.store_max_block, d.voxels, d.max, d.mean,
              d.flipped, fe, fb);
  EXPECT_EQ(d.missing, 0u);
  EXPECT_LT(d.mean, 0.002);
  EXPECT_LT(d.flipped, d.voxels / 1000);
  EXPECT_GE(fb, fe - 0.01);
  // Under a budget that holds everything, nothing changes at all.
  options.store_budget_bytes = se.store_bytes + 1;
  const ProbabilisticFusion roomy = Fuse(options, data);
  EXPECT_EQ(roomy.Stats().store_coarsened_views, 0);
  EXPECT_EQ(CompareH(exact, roomy, options.surface_threshold).max, 0.0);
}

// A textureless rod 4 mm across and 100 mm long under a dome.
synth::Scene RodScene() {
  synth::Scene scene("rod");
  scene.set_foreground_bbox(Box({-0.02, -0.02, -0.06}, {0.02, 0.02, 0.06}));
  scene.Add(synth::Primitive::Cylinder({0, 0, -0.05}, {0.0, 0.0, 0.05}, 0.002, synth::Material::Flat({0.9f, 0.9f, 0.9f}))
                .Named("rod")
                .Foreground());
  testing::AddDome(&scene);
  return scene;
}

TEST(ProbabilisticFusion, StoreBudgetKeepsThinFeatures) {
  // A 4 mm rod with 2 mm voxels, its voxels activated late: in the first half
  // of the views its depths are weak (c = 0.02, below the activation
  // threshold, as dense maps' thin parts often are), so its voxels are
  // back-filled from those views — coarsened to 4x4 blocks and more under a
  // budget of 1/16 of the store. Blocks where the rod (2 px) meets background
  // must stay foreground: were they background, those views would carve it.
  synth::Scene scene = RodScene();
  const double voxel = 0.002;
  Rendered data = RenderAll(scene, testing::RingRig(12, {-25, 0, 25}, Eigen::Vector3d::Zero(), 0.25, 160, 90, 50));
  for (std::size_t i = 0; i < data.depths.size() / 2; ++i) {
    DepthMap& d = data.depths[i];
    d.confidence.setTo(0.02f, d.label == static_cast<int>(DepthLabel::kForeground));
  }
  FusionOptions options = OptionsFor(scene, voxel);
  options.activation_min_confidence = 0.05;
  options.store_budget_bytes = 0;
  const ProbabilisticFusion exact = Fuse(options, data);
  options.store_budget_bytes = exact.Stats().store_bytes / 16;
  const ProbabilisticFusion budget = Fuse(options, data);
  EXPECT_LE(budget.Stats().store_bytes, options.store_budget_bytes);
  EXPECT_GE(budget.Stats().store_max_block, 4);
  const TriangleMesh thin = synth::GroundTruthMesh(scene, true);
  const MeshMetrics me = Score(exact.ExtractMesh(), synth::GroundTruthMesh(scene), &thin, voxel, scene.foreground_bbox());
  const MeshMetrics mb = Score(budget.ExtractMesh(), synth::GroundTruthMesh(scene), &thin, voxel, scene.foreground_bbox());
  const HDiff d = CompareH(exact, budget, options.surface_threshold);
  std::printf("rod with budget: P %.4f R %.4f thin %.4f (exact P %.4f R %.4f thin %.4f); max |dH| %.3f, mean %.4f, "
              "%zu of %zu flipped\n",
              mb.scores[0].precision, mb.scores[0].recall, mb.scores[0].thin_recall, me.scores[0].precision,
              me.scores[0].recall, me.scores[0].thin_recall, d.max, d.mean, d.flipped, d.voxels);
  EXPECT_GE(me.scores[0].thin_recall, 0.9);
  EXPECT_GE(mb.scores[0].thin_recall, 0.9);
  EXPECT_GE(mb.scores[0].precision, 0.9);
  EXPECT_LT(d.flipped, d.voxels / 500);
}

TEST(ProbabilisticFusion, CoarsenedViewIsConservative) {
  // Coarsening keeps a block's front-most foreground depth: a thin foreground
  // column in front of background stays foreground at every level.
  const PinholeView view = testing::LookAtView({0, -1, 0}, {0, 0, 0}, 64, 48, 40);
  DepthMap d(48, 64);
  for (int r = 0; r < 48; ++r)
    for (int c = 0; c < 64; ++c) {
      const bool rod = c == 33;
      d.depth.at<float>(r, c) = rod ? 1.0f : 0.0f;  // background: nothing hit (sky)
      d.confidence.at<float>(r, c) = 1.0f;
      d.label.at<std::uint8_t>(r, c) =
          static_cast<std::uint8_t>(rod ? DepthLabel::kForeground : DepthLabel::kBackground);
    }
  const BoundingBox volume = Box(Eigen::Vector3d::Constant(-0.2), Eigen::Vector3d::Constant(0.2));
  CompactDepthView v(view, d, volume);
  for (int level = 1; level <= 4; ++level) {
    v = v.Coarsened(0.01);
    ASSERT_EQ(v.block(), 1 << level);
    const int col = 33 / v.block();
    EXPECT_EQ(CompactDepthView::Label(v.at(0, col)), DepthLabel::kForeground);
    EXPECT_NEAR(v.Depth(v.at(0, col)), 1.0, 1e-4);
    EXPECT_EQ(v.at(0, col == 0 ? 1 : 0).depth, CompactDepthView::kBeyond);
    EXPECT_EQ(v.grid_width(), (64 + v.block() - 1) / v.block());
  }
  FusionOptions fo;
  fo.volume = volume;
  fo.voxel_size = 0.004;
  const SurfaceEvidence ev(v, fo);
  float lp;
  double c;
  ASSERT_TRUE(ev.LogProbability(view.Unproject({33.5, 20.5}, 1.0), &lp, &c));
  EXPECT_NEAR(c, 1.0, 1e-3);  // on the rod's surface
  ASSERT_TRUE(ev.LogProbability(view.Unproject({5.5, 20.5}, 1.0), &lp, &c));
  EXPECT_NEAR(c, -1.0, 1e-3);  // free space through the sky
}

TEST(ProbabilisticFusion, BackgroundRaysCarveFreeSpace) {
  // Nothing in V; view 0 claims a foreground patch (an outlier), the others see background through it.
  synth::Scene scene("empty");
  scene.set_foreground_bbox(Box(Eigen::Vector3d::Constant(-0.1), Eigen::Vector3d::Constant(0.1)));
  testing::AddDome(&scene);
  const std::vector<PinholeView> views = testing::SphereRig(12, Eigen::Vector3d::Zero(), 0.6, 160, 90, 40);
  FusionOptions options = OptionsFor(scene, 0.004);
  ProbabilisticFusion fusion(options);
  DepthMap outlier = ExactDepth(scene, views[0]);
  const cv::Rect patch(70, 35, 20, 20);
  outlier.depth(patch).setTo(0.6f);  // the patch lies around V's centre
  outlier.label(patch).setTo(static_cast<int>(DepthLabel::kForeground));
  fusion.Integrate(views[0], outlier);
  // Alone, the outlier is a confident surface.
  const Eigen::Vector3i centre_voxel = fusion.VoxelIndex(views[0].Unproject({80, 45}, 0.6));
  EXPECT_GT(fusion.SurfaceProbability(centre_voxel), 0.8);
  for (std::size_t i = 1; i < views.size(); ++i) fusion.Integrate(views[i], ExactDepth(scene, views[i]));

  const double p_free = SurfaceEvidence::Probability(-1.0, options.sigma_s, options.probability_clamp);
  std::size_t active = 0, above = 0, only_free = 0;
  double max_only_free_error = 0;
  fusion.ForEachVoxel([&](const Eigen::Vector3i& v, double sum, int n) {
    ++active;
    const double h = std::exp(sum / n);
    above += h >= options.surface_threshold;
    // Voxels in front of the patch by more than the margin are free in every view.
    const Eigen::Vector3d x = fusion.VoxelCenter(v);
    Eigen::Vector2d px;
    const double z = views[0].Project(x, &px);
    if (z < 0.6 - 2 * options.SigmaV() && patch.contains(cv::Point(static_cast<int>(px.x()), static_cast<int>(px.y()))) &&
        px.x() > patch.x + 1 && px.y() > patch.y + 1 && px.x() < patch.br().x - 1 && px.y() < patch.br().y - 1) {
      ++only_free;
      max_only_free_error = std::max(max_only_free_error, std::abs(h - p_free));
    }
  });
  EXPECT_GT(active, 100u);
  EXPECT_EQ(above, 0u) << "every voxel of the outlier's band is seen as free space by the other views";
  EXPECT_GT(only_free, 10u);
  EXPECT_LT(max_only_free_error, 1e-6) << "a voxel seen only as free space has H = P(c = -1)";
  EXPECT_LT(p_free, options.surface_threshold);
  EXPECT_EQ(fusion.SurfaceProbability(centre_voxel) < options.surface_threshold, true);
  EXPECT_EQ(fusion.ExtractMesh().triangles.size(), 0u);
}

TEST(ProbabilisticFusion, ThinCylinderTwoVoxelsAcrossSurvives) {
  // A textureless rod 4 mm across, fused with 2 mm voxels.
  synth::Scene scene = RodScene();
  ASSERT_TRUE(scene.primitive(0).thin);
  const double voxel = 0.002;
  const Rendered data =
      RenderAll(scene, testing::RingRig(12, {-25, 0, 25}, Eigen::Vector3d::Zero(), 0.25, 160, 90, 50));
  const ProbabilisticFusion fusion = Fuse(OptionsFor(scene, voxel), data);
  const TriangleMesh mesh = fusion.ExtractMesh();
  const TriangleMesh thin = synth::GroundTruthMesh(scene, true);
  ASSERT_GT(thin.triangles.size(), 0u);
  const MeshMetrics m = Score(mesh, synth::GroundTruthMesh(scene), &thin, voxel, scene.foreground_bbox());
  std::printf("rod: %zu triangles; P %.4f R %.4f thin recall %.4f at %.0f mm\n", mesh.triangles.size(),
              m.scores[0].precision, m.scores[0].recall, m.scores[0].thin_recall, voxel * 1000);
  EXPECT_GE(m.scores[0].thin_recall, 0.9);
  EXPECT_GE(m.scores[0].precision, 0.9);
}

TEST(ProbabilisticFusion, RejectsBadOptionsAndSizes) {
  FusionOptions o;
  EXPECT_THROW(ProbabilisticFusion{o}, OptionError);  // empty V
  o.volume = Box(Eigen::Vector3d::Zero(), Eigen::Vector3d::Ones());
  o.voxel_size = 0;
  EXPECT_THROW(ProbabilisticFusion{o}, OptionError);
  o.voxel_size = 0.01;
  o.sigma_s = -1;
  EXPECT_THROW(ProbabilisticFusion{o}, OptionError);
  o.sigma_s = 1.3;  // a free-space vote would stay above 0.2: nothing could be carved
  EXPECT_THROW(ProbabilisticFusion{o}, OptionError);
  o.sigma_s = 0.7;
  o.free_space_margin = 5;  // beyond the band
  EXPECT_THROW(ProbabilisticFusion{o}, OptionError);
  o.free_space_margin = 0;
  ProbabilisticFusion f(o);
  const PinholeView view = testing::LookAtView({2, 0, 0.5}, {0.5, 0.5, 0.5}, 64, 48, 40);
  EXPECT_THROW(f.Integrate(view, DepthMap(10, 10)), std::invalid_argument);
  MeshingOptions mo;
  mo.min_views = 0;
  EXPECT_THROW(f.ExtractMesh(mo), OptionError);
}

TEST(ProbabilisticFusion, WritesVdb) {
  const synth::Scene scene = SphereScene();
  const Rendered data = RenderAll(scene, testing::SphereRig(8, Eigen::Vector3d::Zero(), 0.6, 80, 45, 40));
  const ProbabilisticFusion fusion = Fuse(OptionsFor(scene, 0.008), data);
  const auto path = std::filesystem::temp_directory_path() / ("lfrecon_fusion_test_" + std::to_string(getpid()) + ".vdb");
  fusion.WriteVdb(path);
  ASSERT_TRUE(std::filesystem::exists(path));
  EXPECT_GT(std::filesystem::file_size(path), 1000u);
  std::filesystem::remove(path);
  EXPECT_THROW(fusion.WriteVdb("/nonexistent-dir/x.vdb"), std::runtime_error);
}

}  // namespace
}  // namespace lfrecon
