#include "synth/writer.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>

#include "io/colmap_model.h"
#include "io/depth_map_io.h"
#include "io/frame_source.h"
#include "io/ply.h"
#include "io/transforms_json.h"
#include "util/error.h"

namespace lfrecon::synth {
namespace {
namespace fs = std::filesystem;

fs::path TempDir(const std::string& name) {
  const fs::path dir =
      fs::temp_directory_path() / ("lfrecon_synth_writer_" + name + "_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  return dir;
}

double PoseDistance(const Rigid3d& a, const Rigid3d& b) {
  return (a.rotation.toRotationMatrix() - b.rotation.toRotationMatrix()).norm() +
         (a.translation - b.translation).norm();
}

TEST(WriteSynthDataset, WritesTheFigurinesLayoutAndReadsBack) {
  SynthOptions o;
  o.scene = "tabletop";
  o.frames = 10;
  o.width = 96;
  o.height = 54;
  o.render.quantize = true;  // so PNGs read back exactly
  const SynthSequence seq = SynthSequence::Create(o);
  SynthWriteOptions w;
  w.out_dir = TempDir("png");
  w.depth_every = 4;
  const SynthWriteSummary summary = WriteSynthDataset(seq, w);
  EXPECT_EQ(summary.frames, 10);
  EXPECT_EQ(summary.depth_maps, 3);  // 0, 4, 8
  EXPECT_GT(summary.mesh_triangles, summary.thin_triangles);
  EXPECT_GT(summary.thin_triangles, 0u);

  for (const char* f :
       {"images/00000.png", "images/00009.png", "sparse/cameras.txt", "sparse/images.txt",
        "sparse/points3D.txt", "transforms.json", "depth/depth_0000.exr", "depth/depth_0004.exr",
        "depth/depth_0008.exr", "gt_mesh.ply", "gt_thin.ply", "scene.json"})
    EXPECT_TRUE(fs::exists(w.out_dir / f)) << f;
  EXPECT_FALSE(fs::exists(w.out_dir / "depth/depth_0001.exr"));
  EXPECT_FALSE(fs::exists(w.out_dir / "images/00010.png"));

  // COLMAP model: the camera and every pose as generated (text keeps 9 digits).
  const ColmapModel model = ReadColmapModelText(w.out_dir / "sparse");
  ASSERT_EQ(model.cameras.size(), 1u);
  const Camera& cam = model.cameras.begin()->second;
  EXPECT_EQ(cam.model, CameraModelId::kPinhole);
  EXPECT_EQ(cam.width, 96);
  EXPECT_EQ(cam.height, 54);
  for (int k = 0; k < 4; ++k) EXPECT_NEAR(cam.params[k], seq.camera().params[k], 1e-5);
  ASSERT_EQ(model.images.size(), 10u);
  for (int i = 0; i < 10; ++i) {
    EXPECT_EQ(model.images[i].name, SynthSequence::ImageName(i));
    EXPECT_LT(PoseDistance(model.images[i].cam_from_world, seq.cam_from_world(i)), 1e-6) << i;
  }

  // transforms.json: the same poses after the OpenGL/NeRF round trip.
  const std::vector<TransformsFrame> frames = ReadTransformsJson(w.out_dir / "transforms.json");
  ASSERT_EQ(frames.size(), 10u);
  for (int i = 0; i < 10; ++i) {
    EXPECT_EQ(frames[i].file_path, "images/" + SynthSequence::ImageName(i));
    EXPECT_LT(PoseDistance(frames[i].cam_from_world, seq.cam_from_world(i)), 1e-6) << i;
    EXPECT_NEAR(frames[i].camera.fx(), seq.camera().fx(), 1e-5);
    EXPECT_NEAR(frames[i].camera.cx(), 48.0, 1e-9);
  }

  // Depth: float32 EXR equal to the rendered depth.
  const RenderResult r4 = seq.Render(4);
  const cv::Mat depth = ReadExr(w.out_dir / "depth/depth_0004.exr");
  ASSERT_EQ(depth.type(), CV_32F);
  ASSERT_EQ(depth.size(), r4.depth.size());
  cv::Mat expected = DepthToFloat(r4.depth);
  EXPECT_EQ(cv::norm(depth, expected, cv::NORM_INF), 0.0);
  EXPECT_GT(cv::countNonZero(depth), 96 * 54 / 2);

  // Images: 8-bit PNG of the quantised render.
  const cv::Mat img = ReadImageFloat(w.out_dir / "images/00004.png");
  EXPECT_LT(cv::norm(img, r4.image, cv::NORM_INF), 1e-6);

  // Meshes and scene.json.
  const TriangleMesh mesh = ReadPly(w.out_dir / "gt_mesh.ply"), thin = ReadPly(w.out_dir / "gt_thin.ply");
  EXPECT_EQ(mesh.triangles.size(), summary.mesh_triangles);
  EXPECT_EQ(thin.triangles.size(), summary.thin_triangles);
  EXPECT_EQ(mesh.vertices.size(), seq.GroundTruthMesh().vertices.size());
  nlohmann::json j;
  std::ifstream(w.out_dir / "scene.json") >> j;
  EXPECT_EQ(j["scene"], "tabletop");
  EXPECT_EQ(j["seed"], 1);
  EXPECT_EQ(j["frames"], 10);
  EXPECT_EQ(j["width"], 96);
  EXPECT_EQ(j["height"], 54);
  EXPECT_NEAR(j["hfov_deg"].get<double>(), 55.0, 1e-9);
  const BoundingBox& V = seq.scene().foreground_bbox();
  for (int k = 0; k < 3; ++k) {
    EXPECT_DOUBLE_EQ(j["foreground_bbox_min"][k].get<double>(), V.min[k]);
    EXPECT_DOUBLE_EQ(j["foreground_bbox_max"][k].get<double>(), V.max[k]);
  }
  EXPECT_EQ(j["units"], "metres");
  fs::remove_all(w.out_dir);
}

TEST(WriteSynthDataset, JpegAndNoDepth) {
  SynthOptions o;
  o.scene = "sphere";
  o.frames = 3;
  o.width = 64;
  o.height = 36;
  const SynthSequence seq = SynthSequence::Create(o);
  SynthWriteOptions w;
  w.out_dir = TempDir("jpg");
  w.format = "jpg";
  w.depth_every = 0;
  w.write_meshes = false;
  WriteSynthDataset(seq, w);
  EXPECT_TRUE(fs::exists(w.out_dir / "images/00002.jpg"));
  EXPECT_FALSE(fs::exists(w.out_dir / "depth"));
  EXPECT_FALSE(fs::exists(w.out_dir / "gt_mesh.ply"));
  const ColmapModel model = ReadColmapModelText(w.out_dir / "sparse");
  ASSERT_EQ(model.images.size(), 3u);
  EXPECT_EQ(model.images[2].name, "00002.jpg");
  // JPEG is lossy but close.
  const cv::Mat img = ReadImageFloat(w.out_dir / "images/00001.jpg");
  cv::Mat diff;
  cv::absdiff(img, seq.Render(1).image, diff);
  EXPECT_LT(cv::mean(diff)[0], 0.03);
  fs::remove_all(w.out_dir);

  w.format = "tiff";
  EXPECT_THROW(WriteSynthDataset(seq, w), OptionError);
}

}  // namespace
}  // namespace lfrecon::synth
