#include "synth/writer.h"

#include <spdlog/spdlog.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cstdio>
#include <fstream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <system_error>

#include "io/colmap_model.h"
#include "io/depth_map_io.h"
#include "io/frame_source.h"
#include "io/ply.h"
#include "io/transforms_json.h"
#include "synth/renderer.h"
#include "util/error.h"
#include "util/progress.h"

namespace lfrecon::synth {
namespace fs = std::filesystem;

namespace {

void MakeDir(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw InputError(dir.string(), "cannot create folder: " + ec.message());
}

nlohmann::json SceneJson(const SynthSequence& seq, const SynthWriteOptions& options) {
  const BoundingBox& V = seq.scene().foreground_bbox();
  const int S = seq.render_options().supersampling;
  nlohmann::json j;
  j["scene"] = seq.scene().name();
  j["seed"] = seq.seed();
  j["frames"] = seq.NumFrames();
  j["width"] = seq.camera().width;
  j["height"] = seq.camera().height;
  j["hfov_deg"] = seq.hfov_deg();
  j["path"] = PathTypeName(seq.path().type);
  j["loops"] = seq.path().loops;
  j["samples"] = S * S;
  j["noise_sigma"] = seq.render_options().noise_sigma;
  j["format"] = options.format;
  if (options.format == "jpg") j["jpeg_quality"] = options.jpeg_quality;
  const DegradationOptions& d = seq.degradation();
  j["exposure_drift"] = d.exposure_drift;
  j["pose_rotation_deg"] = d.pose_rotation_deg;
  j["pose_translation_mm"] = d.pose_translation_mm;
  j["motion_blur"] = d.motion_blur;
  if (d.pose_rotation_deg > 0 || d.pose_translation_mm > 0) {
    // The true poses, so a reader can measure pose error and its refinement.
    nlohmann::json poses = nlohmann::json::array();
    for (const Rigid3d& p : seq.poses())
      poses.push_back({p.rotation.w(), p.rotation.x(), p.rotation.y(), p.rotation.z(), p.translation.x(),
                       p.translation.y(), p.translation.z()});
    j["true_cam_from_world_qwxyz_t"] = poses;
  }
  j["foreground_bbox_min"] = {V.min.x(), V.min.y(), V.min.z()};
  j["foreground_bbox_max"] = {V.max.x(), V.max.y(), V.max.z()};
  j["thin_radius"] = seq.scene().thin_radius();
  j["depth"] = options.depth_every > 0 ? "planar Z along the camera axis, metres, OpenEXR, every " +
                                             std::to_string(options.depth_every) + "-th frame"
                                       : "none";
  j["units"] = "metres";
  j["convention"] =
      "sparse/: COLMAP text, world-to-camera, OpenCV axes; transforms.json: camera-to-world, OpenGL axes "
      "(NeRF)";
  j["generator"] = "lfrecon synth (analytic ray casting)";
  return j;
}

}  // namespace

void SynthWriteOptions::Check() const {
  LFRECON_CHECK_OPTION(!out_dir.empty());
  LFRECON_CHECK_OPTION(format == "png" || format == "jpg");
  LFRECON_CHECK_OPTION(jpeg_quality >= 1 && jpeg_quality <= 100);
  LFRECON_CHECK_OPTION(depth_every >= 0);
}

fs::path SynthDepthPath(const fs::path& out_dir, int i) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "depth_%04d.exr", i);
  return out_dir / "depth" / buf;
}

SynthWriteSummary WriteSynthDataset(const SynthSequence& seq, const SynthWriteOptions& options) {
  options.Check();
  Timer timer;
  const fs::path& out = options.out_dir;
  MakeDir(out / "images");
  MakeDir(out / "sparse");
  if (options.depth_every > 0) MakeDir(out / "depth");
  if (options.write_masks) MakeDir(out / "masks");
  {
    std::error_code ec;
    if (!fs::is_empty(out / "images", ec))
      spdlog::warn("synth: {} is not empty; files from an earlier run that this one does not overwrite stay",
                   (out / "images").string());
  }

  // Poses first: they are cheap and a reader can check them while frames render.
  const int n = seq.NumFrames();
  ColmapModel model;
  model.cameras[1] = seq.camera();
  std::vector<TransformsFrame> frames;
  for (int i = 0; i < n; ++i) {
    ColmapImage image;
    image.image_id = static_cast<std::uint32_t>(i + 1);
    image.camera_id = 1;
    image.name = SynthSequence::ImageName(i, options.format);
    image.cam_from_world = seq.given_cam_from_world(i);  // with the degradation's pose error, if any
    model.images.push_back(image);
    frames.push_back({"images/" + image.name, seq.camera(), seq.given_cam_from_world(i)});
  }
  WriteColmapModelText(model, out / "sparse");
  WriteTransformsJson(frames, out / "transforms.json");
  {
    const fs::path path = out / "scene.json";
    std::ofstream f(path);
    f << SceneJson(seq, options).dump(1) << "\n";
    if (!f) throw InputError(path.string(), "cannot write");
  }

  SynthWriteSummary summary;
  if (options.write_meshes) {
    const TriangleMesh mesh = seq.GroundTruthMesh(false);
    const TriangleMesh thin = seq.GroundTruthMesh(true);
    WritePly(mesh, out / "gt_mesh.ply");
    WritePly(thin, out / "gt_thin.ply");
    summary.mesh_triangles = mesh.triangles.size();
    summary.thin_triangles = thin.triangles.size();
  }

  // Frames in parallel; each render is parallel inside too, TBB balances both.
  Progress progress("synth: frames", n);
  tbb::parallel_for(tbb::blocked_range<int>(0, n, 1), [&](const tbb::blocked_range<int>& range) {
    for (int i = range.begin(); i != range.end(); ++i) {
      const RenderResult r = seq.Render(i);
      WriteImageFloat(out / "images" / SynthSequence::ImageName(i, options.format), r.image,
                      options.jpeg_quality);
      if (options.depth_every > 0 && i % options.depth_every == 0)
        WriteExr(SynthDepthPath(out, i), DepthToFloat(r.depth));
      if (options.write_masks) {
        const fs::path path = out / "masks" / SynthSequence::ImageName(i, "png");  // NNNNN.png whatever the frames' format
        if (!cv::imwrite(path.string(), ForegroundMask(seq.scene(), r.labels)))
          throw InputError(path.string(), "cannot write");
      }
      progress.Advance();
    }
  });
  progress.Finish();
  summary.frames = n;
  summary.depth_maps = options.depth_every > 0 ? (n + options.depth_every - 1) / options.depth_every : 0;
  summary.seconds = timer.Seconds();
  return summary;
}

}  // namespace lfrecon::synth
