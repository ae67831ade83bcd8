// Upper bound for the pipeline: fusion of the figurines' ground-truth depth
// maps (every 8th frame, confidence 1), meshed and scored against gt_mesh.ply
// and gt_thin.ply. Slow (tens of seconds): runs only with LFRECON_FIGURINES=1;
// LFRECON_FIGURINES_VOXEL_MM sets the voxel size (default 2),
// LFRECON_FIGURINES_SIGMA_S and LFRECON_FIGURINES_MARGIN override σ_s and the
// free-space margin, LFRECON_FIGURINES_STEP the activation step,
// LFRECON_FIGURINES_NEAREST=1 selects nearest-pixel sampling, LFRECON_FIGURINES_OUT names a folder for the mesh (PLY)
// and grid (VDB).
#include <gtest/gtest.h>
#include <spdlog/spdlog.h>

#include <cstdlib>
#include <filesystem>

#include "eval/mesh_metrics.h"
#include "fusion/mesh_coloring.h"
#include "fusion/probabilistic_fusion.h"
#include "io/dataset.h"
#include "io/depth_map_io.h"
#include "io/frame_source.h"
#include "io/ply.h"
#include "util/memory.h"
#include "util/progress.h"

namespace lfrecon {
namespace {

namespace fs = std::filesystem;

TEST(FigurinesFusion, GroundTruthDepthUpperBound) {
  if (!std::getenv("LFRECON_FIGURINES")) GTEST_SKIP() << "set LFRECON_FIGURINES=1 to run";
  const fs::path dir = fs::path(LFRECON_SHARED_DIR) / "data" / "figurines";
  if (!fs::exists(dir)) GTEST_SKIP() << dir << " not found";
  const double voxel_mm = std::getenv("LFRECON_FIGURINES_VOXEL_MM") ? std::atof(std::getenv("LFRECON_FIGURINES_VOXEL_MM")) : 2.0;

  DatasetOptions dopt;
  dopt.dataset_dir = dir;
  const Dataset ds = Dataset::Open(dopt);
  const BoundingBox V = ds.bbox();
  BoundingBox inner = V;  // the table top z = 0 lies on V's boundary: foreground only 1 mm inside V
  inner.min.array() += 0.001;
  inner.max.array() -= 0.001;

  FusionOptions options;
  options.volume = V;
  options.voxel_size = voxel_mm / 1000.0;
  if (const char* v = std::getenv("LFRECON_FIGURINES_SIGMA_S")) options.sigma_s = std::atof(v);
  if (const char* v = std::getenv("LFRECON_FIGURINES_MARGIN")) options.free_space_margin = std::atof(v);
  if (const char* v = std::getenv("LFRECON_FIGURINES_STEP")) options.activation_step = std::atof(v);
  if (std::getenv("LFRECON_FIGURINES_NEAREST")) options.sampling = DepthSampling::kNearest;
  ProbabilisticFusion fusion(options);
  std::vector<int> used;
  Timer total;
  double read_s = 0;
  for (int i = 0; i < ds.NumViews(); ++i) {
    const auto path = ds.GroundTruthDepthPath(i);
    if (!path) continue;
    Timer t;
    const PinholeView view = ds.View(i);
    DepthMap d;
    d.depth = ReadDepthMap(*path);
    d.confidence = cv::Mat(d.depth.size(), CV_32F, cv::Scalar(1));
    d.label = cv::Mat(d.depth.size(), CV_8U, cv::Scalar(0));
    for (int r = 0; r < d.depth.rows; ++r)
      for (int c = 0; c < d.depth.cols; ++c) {
        const float z = d.depth.at<float>(r, c);
        if (!(z > 0) || !std::isfinite(z)) continue;
        const bool fg = inner.Contains(view.Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), z));
        d.label.at<std::uint8_t>(r, c) =
            static_cast<std::uint8_t>(fg ? DepthLabel::kForeground : DepthLabel::kBackground);
      }
    read_s += t.Seconds();
    fusion.Integrate(view, d);
    used.push_back(i);
  }
  const double fuse_s = total.Seconds() - read_s;
  Timer mesh_timer;
  TriangleMesh mesh = fusion.ExtractMesh();
  const double mesh_s = mesh_timer.Seconds();

  // Colours from 8 of the frames.
  Timer color_timer;
  std::vector<ColorView> color_views;
  for (std::size_t k = 0; k < used.size(); k += used.size() / 8) {
    ColorView cv;
    cv.view = ds.View(used[k]);
    cv.image = ReadImageFloat(ds.ImagePath(used[k]));
    color_views.push_back(cv);
  }
  ColoringOptions copt;
  copt.depth_tolerance = 2 * options.voxel_size;
  ColorizeMesh(&mesh, color_views, copt);
  const double color_s = color_timer.Seconds();

  const FusionStats st = fusion.Stats();
  std::printf("figurines GT depth: %zu views, voxel %.2f mm, sigma_s %.2f, margin %.2f, grid %dx%dx%d (%.1f M voxels in V)\n",
              used.size(), voxel_mm, options.sigma_s, options.free_space_margin, options.GridSize().x(), options.GridSize().y(), options.GridSize().z(),
              options.GridSize().cast<double>().prod() / 1e6);
  std::printf("  fusion %.1f s (activate %.1f, back-fill %.1f, update %.1f; reading depth %.1f s), mesh %.1f s, colour %.1f s\n",
              fuse_s, st.activate_s, st.backfill_s, st.update_s, read_s, mesh_s, color_s);
  std::printf("  %zu active voxels (%.2f %% of V), grid %.1f MB, depth store %.1f MB, peak RSS %.0f MB\n",
              st.active_voxels, 100.0 * st.active_voxels / options.GridSize().cast<double>().prod(),
              st.grid_bytes / 1e6, st.store_bytes / 1e6, PeakRssBytes() / 1e6);
  std::size_t grey = 0;
  for (const Color3u8& c : mesh.colors) grey += c == Color3u8(128, 128, 128);
  std::printf("  mesh: %zu vertices, %zu triangles, %.1f %% of vertices coloured from %zu frames\n",
              mesh.vertices.size(), mesh.triangles.size(), 100.0 * (mesh.vertices.size() - grey) / mesh.vertices.size(),
              color_views.size());

  if (const char* out = std::getenv("LFRECON_FIGURINES_OUT")) {
    fs::create_directories(out);
    WritePly(mesh, fs::path(out) / "figurines_gt_depth_fusion.ply");
    fusion.WriteVdb(fs::path(out) / "figurines_gt_depth_fusion.vdb");
  }

  Timer eval_timer;
  MeshMetricsOptions mo;
  mo.volume = V;
  const TriangleMesh gt = ReadPly(*ds.GroundTruthMeshPath(false));
  const TriangleMesh thin = ReadPly(*ds.GroundTruthMeshPath(true));
  const MeshMetrics m = EvaluateMesh(mesh, gt, &thin, mo);
  for (const ThresholdScore& s : m.scores)
    std::printf("  tau %2.0f mm: precision %.4f recall %.4f F %.4f thin recall %.4f\n", s.threshold * 1000,
                s.precision, s.recall, s.fscore, s.thin_recall);
  std::printf("  eval %.1f s (%zu / %zu / %zu samples)\n", eval_timer.Seconds(), m.predicted_samples, m.gt_samples,
              m.thin_samples);
  EXPECT_GT(m.Find(0.005)->fscore, 0.5);
}

}  // namespace
}  // namespace lfrecon
