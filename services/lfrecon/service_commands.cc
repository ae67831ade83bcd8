// Client commands of the streaming service: `lfrecon submit` (to lfrecon-ingest),
// `lfrecon status`, `lfrecon export`, `lfrecon cancel` (to lfrecon-aggregate).
#include <spdlog/spdlog.h>

#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <thread>

#include "commands.h"
#include "common/job_store.h"
#include "common/messaging.h"
#include "dataset_flags.h"
#include "service_client.h"
#include "util/error.h"

namespace lfrecon::cli {
namespace fs = std::filesystem;
namespace pb = ::lfrecon::v1;

// Turns an error reply into the CLI's errors (exit 1 for input/job problems, 2 for usage).
[[noreturn]] void Rethrow(const svc::ServiceError& e, const std::string& endpoint) {
  switch (e.code()) {
    case pb::ERROR_BAD_REQUEST: throw OptionError(e.what());
    case pb::ERROR_UNKNOWN: throw InputError(endpoint, e.what());
    default: throw InputError(endpoint, std::string(pb::ErrorCode_Name(e.code())) + ": " + e.what());
  }
}

pb::Envelope Call(const Endpoints& e, const std::string& endpoint, const pb::Envelope& req, int timeout_ms) {
  zmq::context_t context(1);
  svc::RequestClient client(context, endpoint, svc::kDefaultMaxMessageBytes, e.Security(endpoint));
  try {
    return client.Call(req, std::chrono::milliseconds(timeout_ms));
  } catch (const svc::ServiceError& e) {
    Rethrow(e, endpoint);
  }
}

void AddEndpointFlags(CLI::App* cmd, Endpoints* e, bool ingest) {
  if (ingest) cmd->add_option("--ingest", e->ingest, "lfrecon-ingest endpoint (default $LFRECON_INGEST or loopback)");
  cmd->add_option("--aggregate", e->aggregate, "lfrecon-aggregate endpoint (default $LFRECON_AGGREGATE or loopback)");
  cmd->add_option("--timeout-ms", e->timeout_ms, "How long to wait for a reply")->capture_default_str();
  cmd->add_option("--key", e->key, "This client's CURVE key file (lfrecon keygen --role client; default $LFRECON_KEY)");
  if (ingest)
    cmd->add_option("--ingest-key", e->ingest_key, "lfrecon-ingest's public key file (default $LFRECON_INGEST_KEY)");
  cmd->add_option("--aggregate-key", e->aggregate_key,
                  "lfrecon-aggregate's public key file (default $LFRECON_AGGREGATE_KEY)");
  cmd->add_flag("--insecure", e->insecure, "Allow plain TCP: no authentication, no encryption");
}

namespace {

std::string Abs(const fs::path& p) { return p.empty() ? std::string() : fs::absolute(p).lexically_normal().string(); }

nlohmann::json StatusJson(const std::string& job, const pb::JobStatus& s) {
  return {{"job", job},
          {"state", pb::JobState_Name(s.state()).substr(6)},
          {"views", s.num_views()},
          {"frames_spooled", s.frames_spooled()},
          {"sparse_done", s.sparse_done()},
          {"dense_done", s.dense_done()},
          {"views_fused", s.views_fused()},
          {"masked_views", s.masked_views()},
          {"leases_expired", s.leases_expired()},
          {"active_voxels", s.active_voxels()},
          {"triangles", s.triangles()},
          {"seconds", s.seconds()},
          {"message", s.message()}};
}

}  // namespace

bool Ended(pb::JobState s) { return s == pb::STATE_DONE || s == pb::STATE_FAILED || s == pb::STATE_CANCELLED; }

pb::JobStatus GetStatus(const Endpoints& e, const std::string& job) {
  pb::Envelope req = svc::NewEnvelope(job);
  req.mutable_status();
  return Call(e, e.aggregate, req, e.timeout_ms).job_status();
}

// Polls until the job ends (or `timeout_s` passes); prints progress to stderr.
pb::JobStatus WaitFor(const Endpoints& e, const std::string& job, double timeout_s) {
  const auto start = std::chrono::steady_clock::now();
  while (true) {
    const pb::JobStatus s = GetStatus(e, job);
    if (Ended(s.state())) return s;
    if (std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count() > timeout_s)
      throw InputError(job, "still " + pb::JobState_Name(s.state()) + " after " + std::to_string(timeout_s) + " s");
    spdlog::debug("{}: {} frames, {} sparse, {} fused of {}", job, s.frames_spooled(), s.sparse_done(),
                  s.views_fused(), s.num_views());
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
  }
}

int PrintStatus(const std::string& job, const pb::JobStatus& s, bool json) {
  if (json) {
    std::cout << StatusJson(job, s).dump(2) << "\n";
  } else {
    std::cout << job << ": " << pb::JobState_Name(s.state()).substr(6) << ", " << s.views_fused() << "/"
              << s.num_views() << " views fused (" << s.frames_spooled() << " frames spooled, " << s.sparse_done()
              << " sparse, " << s.dense_done() << " dense), " << s.seconds() << " s";
    if (s.masked_views()) std::cout << ", " << s.masked_views() << " with their mask's free space";
    if (s.leases_expired()) std::cout << ", " << s.leases_expired() << " tasks re-issued";
    if (!s.message().empty()) std::cout << ": " << s.message();
    std::cout << "\n";
  }
  return s.state() == pb::STATE_FAILED ? 1 : 0;
}

void JobOptionFlags::AddTo(CLI::App* cmd) {
  cmd->add_option("--voxel-mm", voxel_mm, "Voxel edge in mm (default: the longest side of V / 256)");
  cmd->add_option("--sigma-s", sigma_s, "σ_s of the fusion (as lfrecon run)");
  cmd->add_flag("--no-densify", no_densify, "Fuse the filtered sparse maps (as lfrecon run)");
  cmd->add_flag("--all-views", all_views,
                "Process every view (as lfrecon run --all-views); by default a dense video's views are selected "
                ">= 2 deg apart");
  cmd->add_option("--view-step-deg", view_step_deg,
                  "Degrees between consecutive selected views (as lfrecon run --view-step-deg; default 2)");
  cmd->add_option("--color-views", color_views, "Frames used to colour the mesh (0: none)")->capture_default_str();
  cmd->add_option("--max-frame-gap", max_frame_gap,
                  "Views more than this many frames apart are never neighbours (as lfrecon run --max-frame-gap; 0: "
                  "no limit; default 1000). With a bound, a stream's views are processed while it is open, 2 gaps "
                  "behind its newest frame; without, after its end");
  cmd->add_flag("--no-mask-free-space", no_mask_free_space,
                "With masks (masks/, an alpha channel, mask_path; each frame carries its mask to the service): use "
                "them for V only (as lfrecon run --no-mask-free-space). By default the fusion also takes every pixel "
                "more than 2 px outside its mask as empty space through V");
  cmd->add_flag("--no-geometric-consistency", no_geometric_consistency,
                "Fuse every propagated depth (as lfrecon run --no-geometric-consistency). By default a view's "
                "foreground depths that are not its own filtered ones are kept only where 4 of the dense maps of "
                "the views 1, 2, 4 and 8 places before and after it in the plan see the same point");
  cmd->add_flag("--mask-carving", mask_carving,
                "With masks: the refined mesh (lfrecon export --refine) also carves the fused voxels that lie outside "
                "a carving frame's mask (more than 2 px and the voxel's own size from its object) before the "
                "photo-consistency carving, as lfrecon run --mask-carving. Off by default: masks that miss thin "
                "parts lose them (docs/benchmarks.md)");
}

pb::JobOptions JobOptionFlags::ToProto() const {
  if (voxel_mm < 0 || sigma_s < 0) throw OptionError("--voxel-mm and --sigma-s must be positive");
  pb::JobOptions o;
  o.set_voxel_size(voxel_mm / 1000.0);
  o.set_sigma_s(sigma_s);
  o.set_no_densify(no_densify);
  o.set_color_views(color_views);
  o.set_all_views(all_views);
  if (max_frame_gap != -1) o.set_max_frame_gap(max_frame_gap);
  if (view_step_deg) o.set_view_step_deg(*view_step_deg);
  o.set_no_mask_free_space(no_mask_free_space);
  o.set_mask_carving(mask_carving);
  o.set_no_geometric_consistency(no_geometric_consistency);
  svc::JobPipelineOptions(o);  // every job option checked here, as lfrecon run does (exit 2)
  return o;
}

void AddServiceCommands(CLI::App& root, int* exit_code) {
  {
    struct Args {
      DatasetFlags data;
      Endpoints ep;
      JobOptionFlags job;
      bool wait = false;
      double wait_s = 3600;
    };
    auto a = std::make_shared<Args>();
    auto* cmd = root.add_subcommand(
        "submit",
        "Submit a job to the streaming service; prints its id. lfrecon-ingest opens the dataset as lfrecon run does "
        "(the paths are read on its machine) and stores each frame with its object mask when the dataset has masks "
        "(DATASET/masks/ or --masks, an alpha channel, mask_path): V and the fusion's free space come from them as in "
        "lfrecon run");
    a->data.AddTo(cmd);
    AddEndpointFlags(cmd, &a->ep, true);
    a->job.AddTo(cmd);
    cmd->add_flag("--wait", a->wait, "Wait until the job ends and print its status");
    cmd->add_option("--wait-s", a->wait_s, "With --wait: give up after this many seconds")->capture_default_str();
    cmd->callback([a, exit_code] {
      const DatasetOptions d = a->data.Resolve();
      pb::Envelope req = svc::NewEnvelope();
      pb::JobSpec* spec = req.mutable_submit()->mutable_spec();
      spec->set_dataset_dir(Abs(d.dataset_dir));
      spec->set_images_dir(Abs(d.images_dir));
      spec->set_video_path(Abs(d.video_path));
      spec->set_colmap_dir(Abs(d.colmap_dir));
      spec->set_transforms_path(Abs(d.transforms_path));
      spec->set_masks_dir(Abs(d.masks_dir));
      spec->set_max_image_size(static_cast<std::uint32_t>(d.max_image_size));
      for (double v : a->data.bbox) spec->add_bbox(v);
      *spec->mutable_options() = a->job.ToProto();
      const pb::Envelope reply = Call(a->ep, a->ep.ingest, req, a->ep.timeout_ms);
      const std::string job = reply.submit_reply().job_id();
      std::cout << job << "\n" << std::flush;
      spdlog::info("submitted {} ({} views)", job, reply.submit_reply().num_views());
      *exit_code = a->wait ? PrintStatus(job, WaitFor(a->ep, job, a->wait_s), false) : 0;
    });
  }
  {
    struct Args {
      std::string job;
      Endpoints ep;
      bool wait = false, json = false;
      double wait_s = 3600;
    };
    auto a = std::make_shared<Args>();
    auto* cmd = root.add_subcommand("status", "State and progress of a service job");
    cmd->add_option("job", a->job, "Job id (from lfrecon submit)")->required();
    AddEndpointFlags(cmd, &a->ep, false);
    cmd->add_flag("--wait", a->wait, "Wait until the job ends");
    cmd->add_option("--wait-s", a->wait_s, "With --wait: give up after this many seconds")->capture_default_str();
    cmd->add_flag("--json", a->json, "JSON output");
    cmd->callback([a, exit_code] {
      const pb::JobStatus s = a->wait ? WaitFor(a->ep, a->job, a->wait_s) : GetStatus(a->ep, a->job);
      *exit_code = PrintStatus(a->job, s, a->json);
    });
  }
  {
    struct Args {
      std::string job;
      fs::path out;
      Endpoints ep;
      bool refine = false;
    };
    auto a = std::make_shared<Args>();
    auto* cmd = root.add_subcommand("export", "Mesh of a service job (what is fused so far while it runs)");
    cmd->add_option("job", a->job, "Job id")->required();
    cmd->add_option("-o,--out", a->out, "Output PLY")->required();
    cmd->add_flag("--refine", a->refine,
                  "Refined mesh (voxel carving + screened Poisson) as lfrecon run's mesh.ply; mid-stream, of the "
                  "views fused so far. The aggregator first re-fuses the job's stored depth maps (about the job's "
                  "fusion time) and keeps serving meanwhile; waits up to 30 min (or --timeout-ms)");
    AddEndpointFlags(cmd, &a->ep, false);
    cmd->callback([a, exit_code] {
      pb::Envelope req = svc::NewEnvelope(a->job);
      req.mutable_export_request()->set_refine(a->refine);
      // Waits at least 2 min, 30 min with --refine (a queued refinement waits for the one before it).
      const int wait_ms = std::max(a->ep.timeout_ms, a->refine ? 1800000 : 120000);
      const pb::Envelope reply = Call(a->ep, a->ep.aggregate, req, wait_ms);
      const pb::ExportReply& r = reply.export_reply();
      if (!a->out.parent_path().empty()) fs::create_directories(a->out.parent_path());
      std::ofstream f(a->out, std::ios::binary);
      f.write(r.ply().data(), static_cast<std::streamsize>(r.ply().size()));
      if (!f) throw InputError(a->out.string(), "cannot write");
      std::cout << "wrote " << a->out.string() << " (" << r.vertices() << " vertices, " << r.triangles()
                << " triangles) from " << r.views_fused() << " fused views" << (r.complete() ? "" : " (job still running)")
                << "\n";
      *exit_code = 0;
    });
  }
  {
    struct Args {
      std::string job;
      Endpoints ep;
    };
    auto a = std::make_shared<Args>();
    auto* cmd = root.add_subcommand("cancel", "Cancel a service job");
    cmd->add_option("job", a->job, "Job id")->required();
    AddEndpointFlags(cmd, &a->ep, false);
    cmd->callback([a, exit_code] {
      pb::Envelope req = svc::NewEnvelope(a->job);
      req.mutable_cancel();
      const pb::JobStatus s = Call(a->ep, a->ep.aggregate, req, a->ep.timeout_ms).job_status();
      if (s.state() != pb::STATE_CANCELLED)
        throw InputError(a->job, "not cancelled: the job had already ended (" + pb::JobState_Name(s.state()).substr(6) + ")");
      std::cout << a->job << ": cancelled\n";
      *exit_code = 0;
    });
  }
}

}  // namespace lfrecon::cli
