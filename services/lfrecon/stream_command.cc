// `lfrecon stream`: a client-pushed job (proto/README.md "Streams"). Opens a
// job on lfrecon-ingest, prints its id, pushes each frame as the job store
// keeps it (the image file's bytes as on disk, a video frame as 8-bit lossless
// PNG; StoreFrameEncoder) with its camera and, when the dataset has masks,
// its object mask as lfrecon run reads it, at most the granted credits in
// flight, optionally paced (--rate), then ends the stream. The cameras and V
// are this client's (the dataset opened here, as `lfrecon run` opens it), so
// the job computes what `lfrecon run` computes on the same frames.
#include <spdlog/spdlog.h>

#include <filesystem>
#include <fstream>
#include <iostream>
#include <nlohmann/json.hpp>
#include <thread>

#include "commands.h"
#include "common/stream_client.h"
#include "dataset_flags.h"
#include "service_client.h"
#include "util/error.h"
#include "util/progress.h"

namespace lfrecon::cli {
namespace fs = std::filesystem;

namespace {

// Writes the job's mesh so far to `out` (atomically: a temporary name, then a
// rename, so a viewer never reads half a file). False while the aggregator
// has no mesh for the job yet (the stream is still open, or nothing is fused).
bool FollowExport(const Endpoints& ep, const std::string& job, const fs::path& out, bool* complete) {
  pb::Envelope req = svc::NewEnvelope(job);
  req.mutable_export_request()->set_refine(false);
  zmq::context_t context(1);
  svc::RequestClient client(context, ep.aggregate, svc::kDefaultMaxMessageBytes, ep.Security(ep.aggregate));
  const auto reply = client.Request(req, std::chrono::milliseconds(std::max(ep.timeout_ms, 120000)));
  if (!reply || reply->has_error() || !reply->has_export_reply()) return false;
  const pb::ExportReply& r = reply->export_reply();
  if (r.triangles() == 0 && !r.complete()) return false;
  if (!out.parent_path().empty()) fs::create_directories(out.parent_path());
  const fs::path tmp = out.string() + ".tmp";
  {
    std::ofstream f(tmp, std::ios::binary);
    f.write(r.ply().data(), static_cast<std::streamsize>(r.ply().size()));
    if (!f) throw InputError(tmp.string(), "cannot write");
  }
  fs::rename(tmp, out);
  *complete = r.complete();
  spdlog::info("{}: {} triangles from {} fused views{}", out.string(), r.triangles(), r.views_fused(),
               r.complete() ? " (complete)" : "");
  return true;
}

}  // namespace

void AddStreamCommand(CLI::App& root, int* exit_code) {
  struct Args {
    DatasetFlags data;
    Endpoints ep;
    JobOptionFlags job;
    double rate = 0;
    int credits = 8;
    bool wait = false;
    fs::path follow, stats;
    double follow_s = 3, wait_s = 3600;
  };
  auto a = std::make_shared<Args>();
  auto* cmd = root.add_subcommand(
      "stream",
      "Stream a dataset's frames to the service as a live camera would (a client-pushed job): opens the job, prints "
      "its id, pushes each frame as stored on disk (a video frame as lossless PNG) with its camera and, when the "
      "dataset has masks (masks/ or --masks, an alpha channel, mask_path), its object mask (V and the fusion's free "
      "space then come from them as in lfrecon run), ends the stream. "
      "With --max-frame-gap N its views are planned and fused while it streams (2 N frames behind the newest), the "
      "rest after its end; without, all after its end. It computes what lfrecon run computes on the same frames "
      "(with the same --max-frame-gap)");
  a->data.AddTo(cmd);
  AddEndpointFlags(cmd, &a->ep, true);
  a->job.AddTo(cmd);
  cmd->add_option("--rate", a->rate, "Push at most this many frames a second (a live camera's pace; 0: as fast as "
                                     "ingest takes them)")
      ->capture_default_str();
  cmd->add_option("--credits", a->credits,
                  "Frames in flight at most (credit-based flow control; ingest may grant fewer)")
      ->capture_default_str();
  cmd->add_flag("--wait", a->wait, "Wait until the job ends and print its status");
  cmd->add_option("--wait-s", a->wait_s, "With --wait or --follow: give up after this many seconds")
      ->capture_default_str();
  cmd->add_option("--follow", a->follow,
                  "Rewrite this PLY with the mesh fused so far every --follow-s seconds (while streaming with "
                  "--max-frame-gap, else once the stream has ended) until the job ends; implies --wait");
  cmd->add_option("--follow-s", a->follow_s, "Seconds between --follow exports")->capture_default_str();
  cmd->add_option("--stats", a->stats,
                  "Write the stream's figures as JSON (frames, seconds, frames/s, bytes, credits, most in flight)");
  cmd->callback([a, exit_code] {
    if (a->rate < 0 || a->credits < 1 || !(a->follow_s > 0))
      throw OptionError("--rate must be >= 0, --credits >= 1, --follow-s > 0");
    const pb::JobOptions options = a->job.ToProto();
    const DatasetOptions d = a->data.Resolve();
    const Dataset ds = Dataset::Open(d);
    pb::StreamOpen open;
    *open.mutable_spec()->mutable_options() = options;
    for (int k = 0; k < 3; ++k) open.mutable_spec()->add_bbox(ds.bbox().min(k));
    for (int k = 0; k < 3; ++k) open.mutable_spec()->add_bbox(ds.bbox().max(k));
    open.mutable_spec()->set_max_image_size(static_cast<std::uint32_t>(d.max_image_size));
    open.set_credits(static_cast<std::uint32_t>(a->credits));
    const std::chrono::milliseconds timeout(a->ep.timeout_ms);
    zmq::context_t context(1);
    svc::StreamClient client(context, a->ep.ingest, svc::kDefaultMaxMessageBytes, a->ep.Security(a->ep.ingest));
    const bool follow = !a->follow.empty();
    bool follow_complete = false;
    Timer follow_timer;
    auto follow_tick = [&] {
      if (!follow || follow_timer.Seconds() < a->follow_s) return;
      follow_timer.Restart();
      FollowExport(a->ep, client.job_id(), a->follow, &follow_complete);
    };
    pb::StreamEnded ended;
    Timer timer;
    std::uint64_t bytes_sent = 0;
    try {
      const pb::StreamOpened opened = client.Open(open, timeout);
      std::cout << opened.job_id() << "\n" << std::flush;
      if (ds.NumViews() > static_cast<int>(opened.max_frames()))
        throw InputError(opened.job_id(), std::to_string(ds.NumViews()) + " frames, ingest takes at most " +
                                              std::to_string(opened.max_frames()));
      svc::StoreFrameEncoder frames(ds);
      for (int k = 0; k < ds.NumViews(); ++k) {
        if (a->rate > 0) {  // paced as a camera: frame k leaves at k / rate seconds
          const double due = k / a->rate - timer.Seconds();
          if (due > 0) std::this_thread::sleep_for(std::chrono::duration<double>(due));
        }
        const pb::Frame frame = frames.Encode(k, false);  // ingest validates it
        const std::size_t frame_bytes = frame.data().size() + frame.mask().size();  // the mask travels with it
        if (frame_bytes > opened.max_frame_bytes())
          throw InputError(ds.ImagePath(k).string(), std::to_string(frame_bytes) +
                                                         " bytes with its mask, more than ingest takes in a frame (" +
                                                         std::to_string(opened.max_frame_bytes()) + ")");
        bytes_sent += frame_bytes;
        client.Push(frame, timeout);
        follow_tick();
      }
      // Ingest answers the end once every frame is stored and the job is handed on.
      ended = client.End(static_cast<std::uint32_t>(ds.NumViews()), std::max(timeout, std::chrono::milliseconds(600000)));
    } catch (const svc::ServiceError& e) {
      Rethrow(e, a->ep.ingest);
    }
    const double seconds = timer.Seconds();
    const std::string job = client.job_id();
    spdlog::info("{}: {} frames pushed in {:.2f} s ({:.1f} frames/s), {:.0f} bytes a frame, {} credits, at most {} in "
                 "flight (ingest counted {}), {} repeats",
                 job, ds.NumViews(), seconds, ds.NumViews() / std::max(seconds, 1e-9),
                 static_cast<double>(bytes_sent) / ds.NumViews(), client.credits(), client.max_in_flight(),
                 client.max_in_flight_ingest(), client.repeated());
    if (!a->stats.empty()) {
      const auto& v0 = ds.views().front().camera;
      const nlohmann::json j = {{"job", job},
                                {"frames", ds.NumViews()},
                                {"seconds", seconds},
                                {"frames_per_second", ds.NumViews() / std::max(seconds, 1e-9)},
                                {"bytes_sent", bytes_sent},
                                {"bytes_stored", ended.bytes_stored()},
                                {"bytes_per_pixel", static_cast<double>(ended.bytes_stored()) /
                                                        (static_cast<double>(v0.width) * v0.height * ds.NumViews())},
                                {"credits", client.credits()},
                                {"max_in_flight", client.max_in_flight()},
                                {"max_in_flight_ingest", client.max_in_flight_ingest()},
                                {"repeated", client.repeated()}};
      std::ofstream f(a->stats);
      f << j.dump(2) << "\n";
      if (!f) throw InputError(a->stats.string(), "cannot write");
    }
    if (!a->wait && !follow) {
      *exit_code = 0;
      return;
    }
    if (!follow) {
      *exit_code = PrintStatus(job, WaitFor(a->ep, job, a->wait_s), false);
      return;
    }
    // --follow: the mesh so far every few seconds until the job ends, then the final one.
    Timer waited;
    for (;;) {
      const pb::JobStatus s = GetStatus(a->ep, job);
      if (Ended(s.state())) {
        if (s.state() == pb::STATE_DONE) FollowExport(a->ep, job, a->follow, &follow_complete);
        *exit_code = PrintStatus(job, s, false);
        return;
      }
      if (waited.Seconds() > a->wait_s)
        throw InputError(job, "still " + pb::JobState_Name(s.state()) + " after " + std::to_string(a->wait_s) + " s");
      follow_tick();
      std::this_thread::sleep_for(std::chrono::milliseconds(200));
    }
  });
}

}  // namespace lfrecon::cli
