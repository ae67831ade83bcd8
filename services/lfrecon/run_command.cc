// `lfrecon run`: the embedded end-to-end pipeline in one process (depth from
// gradients, filtering, densification, probabilistic fusion, meshing,
// colouring) over one pass of the frames; writes OUT/mesh.ply, mesh_raw.ply,
// grid.vdb, report.json and, on request, per-view depth maps.
#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <filesystem>
#include <iostream>
#include <nlohmann/json.hpp>
#include <optional>

#include "commands.h"
#include "dataset_flags.h"
#include "io/dataset.h"
#include "io/colmap_model.h"
#include "pipeline/embedded_pipeline.h"
#include "pipeline/finish_surface.h"
#include "pipeline/pipeline_flags.h"
#include "poses/pose_refinement.h"
#include "run_outputs.h"
#include "util/error.h"
#include "util/progress.h"

namespace lfrecon::cli {
namespace fs = std::filesystem;

namespace {

struct RunArgs {
  DatasetFlags data;
  fs::path out;
  double voxel_mm = 0;
  bool write_depth = false;
  std::string views;
  bool no_densify = false;
  bool no_refine = false;
  bool poisson = false;
  int color_views = 8;
  double sigma_s = 0;
  std::optional<double> chroma_weight;
  std::optional<double> view_step_deg;
  std::optional<int> refine_depth_views;
  std::optional<int> smooth_iterations;
  std::optional<int> rim_trim_rounds;
  bool no_refine_poses = false;
  bool no_mask_free_space = false;
  bool no_geometric_consistency = false;
  bool mask_carving = false;
  RunOutputFlags outputs;  // mesh formats, point cloud, COLMAP workspace, report.html
  bool all_views = false;
  std::optional<int> max_frame_gap;
};

// OUT/sparse_refined/: the refined poses as a COLMAP text model (undistorted cameras).
void WriteRefinedModel(const Dataset& ds, const std::vector<PinholeView>& views, const fs::path& dir) {
  ColmapModel model;
  for (int i = 0; i < ds.NumViews(); ++i) {
    const std::uint32_t cam_id = static_cast<std::uint32_t>(i + 1);
    model.cameras[cam_id] = ds.UndistortedCamera(i);
    ColmapImage image;
    image.image_id = cam_id;
    image.camera_id = cam_id;
    image.name = ds.views()[static_cast<std::size_t>(i)].name;
    const PinholeView& v = views[static_cast<std::size_t>(i)];
    image.cam_from_world = Rigid3d(Eigen::Quaterniond(v.R).normalized(), v.t);
    model.images.push_back(image);
  }
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw InputError(dir.string(), "cannot create folder: " + ec.message());
  WriteColmapModelText(model, dir);
}

int RunPipeline(const RunArgs& args) {
  if (args.voxel_mm < 0) throw OptionError("--voxel-mm must be positive");
  args.outputs.MeshFormats();  // checked before any work
  if (args.poisson && args.no_refine) throw OptionError("--poisson and --no-refine exclude each other");
  if (args.all_views && !args.views.empty()) throw OptionError("--views and --all-views exclude each other");
  // The flags a service job has too, mapped as the service maps them.
  ReconstructionFlags flags;
  flags.voxel_size = args.voxel_mm / 1000.0;
  flags.sigma_s = args.sigma_s;
  flags.no_densify = args.no_densify;
  flags.color_views = args.color_views;
  flags.all_views = args.all_views;
  flags.max_frame_gap = args.max_frame_gap;
  flags.no_mask_free_space = args.no_mask_free_space;
  flags.no_geometric_consistency = args.no_geometric_consistency;
  flags.mask_carving = args.mask_carving;
  flags.chroma_weight = args.chroma_weight;
  flags.view_step_deg = args.view_step_deg;
  flags.refine_depth_views = args.refine_depth_views;
  flags.smooth_iterations = args.smooth_iterations;
  flags.rim_trim_rounds = args.rim_trim_rounds;
  PipelineOptions options = OptionsFromFlags(flags);
  const Dataset ds = Dataset::Open(args.data.Resolve());
  if (!args.views.empty()) options.views = ParseViewRange(args.views, ds.NumViews());
  options.out_dir = args.out;
  options.write_depth = args.write_depth || args.outputs.NeedsDepth();
  options.refine = !args.no_refine;
  options.refine_options.use_poisson = args.poisson;
  std::vector<PinholeView> views;
  std::vector<std::string> names;
  for (int i = 0; i < ds.NumViews(); ++i) {
    views.push_back(ds.View(i));
    names.push_back(ds.views()[i].name);
  }
  spdlog::info("run: dataset {} ({} views, poses from {}, V from {})",
               ds.root().empty() ? std::string("(explicit sources)") : ds.root().string(), ds.NumViews(),
               ds.pose_source(), ds.bbox_source());
  const Timer whole;  // pose refinement + pipeline: what the frames/s line below divides by
  if (!args.no_refine_poses) {
    const Timer tr;
    // A pass over the frames before the pipeline's own: the poses every stage uses come from it.
    auto frames = ds.OpenFrames();
    const PoseRefinementResult pr = RefinePoses(*frames, views, PoseRefinementOptions{});
    views = pr.views;
    const PoseRefinementStats& ps = pr.stats;
    // report.json gains the pose refinement's figures (written once, by the pipeline).
    options.extra_report["pose_refinement"] = {{"tracks", ps.tracks},
                   {"observations", ps.observations},
                   {"rms_reprojection_px", {ps.rms_reprojection_before_px, ps.rms_reprojection_after_px}},
                   {"median_reprojection_px", {ps.median_reprojection_before_px, ps.median_reprojection_after_px}},
                   {"median_rotation_change_deg", ps.median_rotation_change_deg},
                   {"median_center_change", ps.median_center_change},
                   {"scene_distance", ps.scene_distance},
                   {"seconds", ps.seconds_tracking + ps.seconds_solve},
                   {"cpu_seconds", tr.CpuSeconds()},
                   {"converged", ps.converged}};
    if (!args.out.empty()) WriteRefinedModel(ds, views, args.out / "sparse_refined");
  }
  options.preview_views = args.outputs.previews;
  EmbeddedPipeline pipeline(views, ds.bbox(), options, names);
  const bool mask_free_space = options.mask_free_space.confidence > 0;
  const bool mask_carving = CarvesOutsideMasks(options);
  if (ds.HasMasks() && (mask_free_space || mask_carving)) {
    spdlog::info("run: masks from {}: {}", ds.mask_source(),
                 mask_free_space && mask_carving ? "free space outside them in fusion, carved outside them after"
                 : mask_free_space             ? "free space outside them in fusion"
                                               : "carved outside them after fusion");
    pipeline.SetMasks([&ds](int i) { return ds.ReadMask(i); });
  }
  auto frames = ds.OpenFrames();
  const PipelineResult r = pipeline.Run(*frames);
  if (!args.out.empty()) {
    std::vector<int> all(static_cast<std::size_t>(ds.NumViews()));
    for (int i = 0; i < ds.NumViews(); ++i) all[static_cast<std::size_t>(i)] = i;  // those with depth maps
    WriteRunOutputs(args.outputs, ds, views, all, r.mesh, r.stats.voxel_size, args.out);
  }
  const PipelineStats& s = r.stats;
  std::cout << "wrote " << (args.out / "mesh.ply").string() << " (" << s.mesh_vertices << " vertices, "
            << s.mesh_triangles << " triangles) from " << s.views << " views at " << 1000 * s.voxel_size
            << " mm voxels in " << s.seconds_total << " s, peak RSS " << s.peak_rss_bytes / 1048576 << " MiB; "
            << "report " << (args.out / "report.json").string() << "\n";
  const double wall = whole.Seconds();
  std::cout << "run: " << ds.NumViews() << " frames in " << wall << " s ("
            << (wall > 0 ? ds.NumViews() / wall : 0.0) << " frames/s), " << whole.CpuSeconds()
            << " CPU-s (user + system)\n";
  return 0;
}

}  // namespace

void AddRunCommand(CLI::App& root, int* exit_code) {
  auto args = std::make_shared<RunArgs>();
  auto* cmd = root.add_subcommand(
      "run", "The whole reconstruction in one process: depth (§3), densification (§4), fusion (§5), mesh");
  args->data.AddTo(cmd);
  args->outputs.AddTo(cmd);
  cmd->add_option("--out", args->out, "Output folder (mesh.ply, mesh_raw.ply, grid.vdb, report.json, mesh_turntable.png)")->required();
  cmd->add_option("--voxel-mm", args->voxel_mm, "Voxel edge in mm (default: the longest side of V / 256)");
  cmd->add_flag("--write-depth", args->write_depth, "Also write the fused per-view depth maps (depth/, confidence/ PFM)");
  cmd->add_option("--views", args->views, "Views to process, A:B:STEP (0-based, B exclusive); default: selected "
                   "automatically, views >= 2 deg apart (--view-step-deg; lfrecon info: mean_step_deg; a sequence 2 deg "
                   "apart or more keeps every view). Every frame is still read and serves as a neighbour");
  cmd->add_flag("--all-views", args->all_views,
                "Process every view (no view selection): depth and fusion of each frame, also on a dense video");
  cmd->add_option("--view-step-deg", args->view_step_deg,
                  "Degrees between consecutive selected views (default 2): larger processes fewer views, faster");
  cmd->add_option("--refine-depth-views", args->refine_depth_views,
                  "Neighbours (the widest baselines) each dense depth is searched again over by ZNCC "
                  "(PhotometricRefinementOptions::views; 0: no refinement)");
  cmd->add_option("--rim-trim-rounds", args->rim_trim_rounds,
                  "Rounds of dropping the final mesh's triangles on its open rims, before smoothing (default 1; 0: "
                  "off). Components under 100 vertices stay whole");
  cmd->add_option("--smooth-iterations", args->smooth_iterations,
                  "Taubin smoothing steps of the final mesh (default 6; 0: off). No vertex moves more than a voxel; "
                  "mesh_raw.ply stays unsmoothed");
  cmd->add_option("--max-frame-gap", args->max_frame_gap,
                  "Views more than this many frames apart are never neighbours (0: no limit; default 1000). "
                  "`lfrecon stream --max-frame-gap` with the same bound computes the same mesh");
  cmd->add_flag("--no-refine", args->no_refine,
                "Skip the refinement (voxel carving): mesh.ply is then the fused iso-surface, like mesh_raw.ply");
  cmd->add_flag("--poisson", args->poisson,
                "Mesh the carved surface by screened Poisson instead of marching cubes (smoother, but loses thin parts)");
  cmd->add_flag("--no-densify", args->no_densify, "Fuse the filtered sparse maps without densification (§4)");
  cmd->add_option("--sigma-s", args->sigma_s,
                  "σ_s of the fusion's confidence model (eq. 12-13); default 0.15 for dense maps, 0.7 with --no-densify");
  cmd->add_option("--chroma-weight", args->chroma_weight,
                  "Weight of chroma in the bidirectional photo-consistency ρ (eq. 9), 0..1 (default 0.5: JPEG and video keep chroma at half resolution); 1: plain RGB distance, the paper's");
  cmd->add_flag("--no-refine-poses", args->no_refine_poses,
                "Use the given poses as they are. By default they are first refined against the frames (corner "
                "tracks + bundle adjustment with a prior around each given pose; OUT/sparse_refined/): poses with "
                "the error of a good SfM solution otherwise halve the mesh's quality (docs/benchmarks.md)");
  cmd->add_flag("--no-mask-free-space", args->no_mask_free_space,
                "With masks (masks/, an alpha channel, mask_path): use them for V only. By default the fusion "
                "also takes every pixel more than 2 px outside its mask as empty space through V");
  cmd->add_flag("--no-geometric-consistency", args->no_geometric_consistency,
                "Fuse every propagated depth. By default a foreground depth is kept only where 4 of the dense "
                "maps of the views 1, 2, 4 and 8 places before and after it in the plan see the same point within "
                "1 % (the views' own filtered depths are not checked): the halo that propagation spreads beside "
                "an object goes (docs/benchmarks.md)");
  cmd->add_flag("--mask-carving", args->mask_carving,
                "With masks: also carve the fused voxels that lie outside a carving frame's mask (more than 2 px "
                "and the voxel's own size from its object) before the photo-consistency carving. Off by default: "
                "masks that miss thin parts lose them (docs/benchmarks.md)");
  cmd->add_option("--color-views", args->color_views, "Frames kept to colour the mesh (0: none)")->capture_default_str();
  cmd->callback([args, exit_code] { *exit_code = RunPipeline(*args); });
}

}  // namespace lfrecon::cli
