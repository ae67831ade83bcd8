// The benchmark of `lfrecon poses` (issue 17), in two steps around the CLI:
//   sfm_poses_bench video --dataset GEN_DIR --out STEM    # GEN_DIR's images -> STEM.mkv (FFV1) or STEM.avi (MJPG)
//   sfm_poses_bench align --estimated POSED_DIR --truth GEN_DIR [--mesh IN.ply --mesh-out OUT.ply] [--json F]
// `align` matches views by the number in their names (frame_00042.png <-> 00042.png), aligns the
// estimated cameras to the true ones with a similarity (Umeyama on the centres), prints the
// rotation and centre errors, and maps a mesh reconstructed in the estimated (normalised SfM)
// world into the true metric world, where `lfrecon eval --dataset GEN_DIR` scores it.
// tests/bench/poses_bench.sh runs the whole measurement.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <regex>

#include "io/dataset.h"
#include "io/ply.h"
#include "sfm/video_writer.h"
#include "sfm/world_frame.h"

using namespace lfrecon;
namespace fs = std::filesystem;

namespace {

int FrameNumber(const std::string& name) {
  static const std::regex kDigits("([0-9]+)[^0-9]*$");
  std::smatch m;
  const std::string stem = fs::path(name).stem().string();
  if (!std::regex_search(stem, m, kDigits)) return -1;
  return std::stoi(m[1]);
}

Dataset Open(const fs::path& dir) {
  DatasetOptions o;
  o.dataset_dir = dir;
  return Dataset::Open(o);
}

int Video(const fs::path& dataset_dir, const fs::path& stem, double fps) {
  const Dataset ds = Open(dataset_dir);
  std::string codec;
  const fs::path out = testing::WriteVideo(stem, ds.NumViews(), fps, [&](int i) {
    const cv::Mat m = cv::imread(ds.ImagePath(i).string(), cv::IMREAD_COLOR);
    if (m.empty()) throw std::runtime_error("cannot read " + ds.ImagePath(i).string());
    return m;
  }, &codec);
  std::printf("%s\n", out.c_str());
  spdlog::info("wrote {} frames to {} ({})", ds.NumViews(), out.string(), codec);
  return 0;
}

int Align(const fs::path& estimated_dir, const fs::path& truth_dir, const std::string& mesh_in,
          const std::string& mesh_out, const std::string& json_out, bool per_view) {
  const Dataset est = Open(estimated_dir), truth = Open(truth_dir);
  std::map<int, Rigid3d> truth_by_frame;
  for (const DatasetView& v : truth.views()) truth_by_frame[FrameNumber(v.name)] = v.cam_from_world;
  std::vector<Rigid3d> e, t;
  for (const DatasetView& v : est.views()) {
    const auto it = truth_by_frame.find(FrameNumber(v.name));
    if (it == truth_by_frame.end()) continue;
    e.push_back(v.cam_from_world);
    t.push_back(it->second);
  }
  const Similarity3d A = AlignCameras(e, t);
  const PoseErrors err = ComparePoses(e, t, A, truth.bbox().Center());
  if (per_view) {
    for (std::size_t i = 0; i < e.size(); ++i) {
      const PoseErrors one = ComparePoses({e[i]}, {t[i]}, A, truth.bbox().Center());
      // The error as a rotation of the camera frame (est camera from true camera), in degrees.
      const Eigen::AngleAxisd d(A.TransformPose(e[i]).rotation * t[i].rotation.inverse());
      const Eigen::Vector3d w = d.angle() * d.axis() * 180 / M_PI;
      std::printf("view %zu (%s): rotation %.4f deg (camera frame %.4f %.4f %.4f), centre %.4f %%\n", i,
                  est.views()[i].name.c_str(), one.median_rotation_deg, w.x(), w.y(), w.z(),
                  100 * one.median_center_relative());
    }
  }
  const BoundingBox& V = est.bbox();
  const Eigen::Vector3d vmin = A * V.min, vmax = A * V.max;
  const double up_error_deg =
      std::acos(std::min(1.0, (A.rotation * Eigen::Vector3d::UnitZ()).dot(Eigen::Vector3d::UnitZ()))) * 180 / M_PI;
  std::printf("up (estimated +z in the true world) %.3f deg from the true +z; V's longest side %.3f m (true %.3f m)\n",
              up_error_deg, A.scale * V.Extent().maxCoeff(), truth.bbox().Extent().maxCoeff());
  std::printf(
      "%d views matched of %d true; median rotation error %.4f deg (max %.4f); centre error median %.4f %% (max "
      "%.4f %%) of the camera distance %.3f; scale %.5f; V (in the true world, axis-aligned corners) [%.3f %.3f %.3f] "
      "- [%.3f %.3f %.3f], true V [%.3f %.3f %.3f] - [%.3f %.3f %.3f]\n",
      err.views, truth.NumViews(), err.median_rotation_deg, err.max_rotation_deg, 100 * err.median_center_relative(),
      100 * err.max_center_relative(), err.camera_distance, A.scale, vmin.x(), vmin.y(), vmin.z(), vmax.x(), vmax.y(),
      vmax.z(), truth.bbox().min.x(), truth.bbox().min.y(), truth.bbox().min.z(), truth.bbox().max.x(),
      truth.bbox().max.y(), truth.bbox().max.z());
  if (!mesh_in.empty()) {
    TriangleMesh mesh = ReadPly(mesh_in);
    for (Eigen::Vector3f& v : mesh.vertices) v = (A * v.cast<double>()).cast<float>();
    for (Eigen::Vector3f& n : mesh.normals) n = (A.rotation * n.cast<double>()).cast<float>();
    WritePly(mesh, mesh_out);
    std::printf("%s -> %s (in the true world)\n", mesh_in.c_str(), mesh_out.c_str());
  }
  if (!json_out.empty()) {
    nlohmann::json j = {{"views", err.views},
                        {"true_views", truth.NumViews()},
                        {"median_rotation_deg", err.median_rotation_deg},
                        {"max_rotation_deg", err.max_rotation_deg},
                        {"median_centre_relative", err.median_center_relative()},
                        {"max_centre_relative", err.max_center_relative()},
                        {"camera_distance", err.camera_distance},
                        {"scale", A.scale},
                        {"up_error_deg", up_error_deg},
                        {"volume_longest_side_m", A.scale * V.Extent().maxCoeff()}};
    std::ofstream(json_out) << j.dump(1) << "\n";
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"lfrecon poses benchmark: video from a generated set, alignment to its true cameras"};
  app.require_subcommand(1);
  std::string dataset, out, estimated, truth, mesh_in, mesh_out, json_out;
  double fps = 30;
  auto* video = app.add_subcommand("video", "A dataset's images to a video file");
  video->add_option("--dataset", dataset)->required();
  video->add_option("--out", out, "Output path without extension")->required();
  video->add_option("--fps", fps);
  auto* align = app.add_subcommand("align", "Pose errors after a similarity alignment; a mesh mapped to the true world");
  align->add_option("--estimated", estimated)->required();
  align->add_option("--truth", truth)->required();
  align->add_option("--mesh", mesh_in);
  align->add_option("--mesh-out", mesh_out);
  align->add_option("--json", json_out);
  bool per_view = false;
  align->add_flag("--per-view", per_view, "Print each view's errors");
  CLI11_PARSE(app, argc, argv);
  try {
    if (video->parsed()) return Video(dataset, out, fps);
    if (!mesh_in.empty() && mesh_out.empty()) throw std::invalid_argument("--mesh needs --mesh-out");
    return Align(estimated, truth, mesh_in, mesh_out, json_out, per_view);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "sfm_poses_bench: %s\n", e.what());
    return 1;
  }
}
