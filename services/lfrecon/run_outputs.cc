#include "run_outputs.h"

#include <spdlog/spdlog.h>

#include <memory>
#include <set>
#include <sstream>

#include "export/export.h"
#include "io/depth_map_io.h"
#include "io/ply.h"
#include "report_html.h"
#include "util/error.h"
#include "util/progress.h"

namespace lfrecon::cli {
namespace fs = std::filesystem;

void RunOutputFlags::AddTo(CLI::App* app) {
  app->add_option("--mesh-format", mesh_format,
                  "Mesh file formats, comma-separated: ply (always written), obj (Wavefront, vertex colours after x y z), glb "
                  "(binary glTF) -> OUT/mesh.obj, OUT/mesh.glb")
      ->capture_default_str();
  app->add_flag("--point-cloud", point_cloud,
                "Also write OUT/points.ply: the fused depth maps back-projected inside V, one coloured point "
                "with a normal per voxel (implies --write-depth)");
  app->add_flag("--export-depth-colmap", export_depth_colmap,
                "Also write OUT/colmap/, a COLMAP dense workspace (undistorted images, sparse/, "
                "stereo/depth_maps and normal_maps as NAME.geometric.bin) for colmap stereo_fusion or "
                "OpenMVS (implies --write-depth)");
  app->add_flag("--no-report-html", no_report_html, "Do not write OUT/report.html");
  app->add_option("--previews", previews,
                  "Views (evenly spread over those processed) with a depth preview (OUT/preview/) and an edge "
                  "preview of the dense stage (OUT/edges/), shown in report.html; 0: none")
      ->capture_default_str()
      ->check(CLI::NonNegativeNumber);
}

std::vector<std::string> RunOutputFlags::MeshFormats() const {
  std::vector<std::string> out;
  std::stringstream ss(mesh_format);
  std::string f;
  while (std::getline(ss, f, ',')) {
    if (f.empty()) continue;
    if (f != "ply" && f != "obj" && f != "glb")
      throw OptionError("--mesh-format: unknown format '" + f + "' (ply, obj, glb)");
    out.push_back(f);
  }
  return out;
}

void WriteRunOutputs(const RunOutputFlags& flags, const Dataset& ds, const std::vector<PinholeView>& views,
                     const std::vector<int>& processed, const TriangleMesh& mesh, double voxel_size,
                     const fs::path& out) {
  for (const std::string& f : flags.MeshFormats()) {
    if (f == "ply") continue;  // the pipeline's own
    Timer t;
    WriteMeshFile(mesh, out / ("mesh." + f));
    spdlog::info("wrote {} in {:.2f} s", (out / ("mesh." + f)).string(), t.Seconds());
  }
  if (flags.NeedsDepth()) {
    // One more pass over the frames: colours for the points, undistorted images for COLMAP.
    Timer t;
    const std::set<int> wanted(processed.begin(), processed.end());
    PointCloudAccumulator cloud(ds.bbox(), voxel_size);
    std::unique_ptr<ColmapWorkspaceWriter> workspace;
    if (flags.export_depth_colmap) workspace = std::make_unique<ColmapWorkspaceWriter>(out / "colmap");
    auto frames = ds.OpenFrames();
    Frame frame;
    int written = 0;
    while (frames->Next(&frame)) {
      if (!wanted.count(frame.index)) continue;
      const fs::path depth_path = out / "depth" / (fs::path(frame.name).stem().string() + ".pfm");
      std::error_code ec;
      if (!fs::is_regular_file(depth_path, ec)) continue;  // a view the pipeline did not process
      const cv::Mat depth = ReadPfm(depth_path);
      const PinholeView& v = views[static_cast<std::size_t>(frame.index)];
      if (flags.point_cloud) cloud.Add(v, depth, frame.image);
      if (workspace) {
        workspace->Add({frame.name, v, frame.image, depth});
      }
      ++written;
    }
    if (written == 0 && flags.NeedsDepth()) spdlog::warn("{}: no depth maps to export", (out / "depth").string());
    if (workspace) {
      workspace->Finish();
      spdlog::info("wrote {} ({} views: colmap stereo_fusion --workspace_path {} --input_type geometric "
                   "--output_path fused.ply)",
                   (out / "colmap").string(), written, (out / "colmap").string());
    }
    if (flags.point_cloud) {
      const TriangleMesh points = cloud.Result();
      WritePly(points, out / "points.ply");
      spdlog::info("wrote {} ({} points at {:.2f} mm) in {:.1f} s", (out / "points.ply").string(),
                   points.vertices.size(), 1000 * voxel_size, t.Seconds());
    }
  }
  if (!flags.no_report_html) {
    ReportHtmlOptions ro;
    ro.gt_mesh = ds.GroundTruthMeshPath();
    ro.gt_thin = ds.GroundTruthMeshPath(true);
    ro.max_previews = flags.previews;
    const fs::path html = WriteReportHtml(out, ro);
    spdlog::info("wrote {}", html.string());
  }
}

}  // namespace lfrecon::cli
