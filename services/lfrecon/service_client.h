#pragma once
// What the service's client commands share (service_commands.cc: submit,
// status, export, cancel; stream_command.cc: stream): endpoints and keys,
// requests with the CLI's errors, waiting for a job, and the job option flags
// (mapped to the pipeline's options by OptionsFromFlags, through JobOptions).
#include <CLI/CLI.hpp>
#include <optional>
#include <string>

#include "common/job_store.h"
#include "common/messaging.h"

namespace lfrecon::cli {
namespace pb = ::lfrecon::v1;

struct Endpoints {
  std::string ingest = svc::EndpointFromEnv("LFRECON_INGEST", svc::kDefaultIngestEndpoint);
  std::string aggregate = svc::EndpointFromEnv("LFRECON_AGGREGATE", svc::kDefaultAggregateEndpoint);
  int timeout_ms = 30000;
  // CURVE (common/auth.h): this client's key file and the daemons' public keys.
  std::string key = svc::EndpointFromEnv("LFRECON_KEY", "");
  std::string ingest_key = svc::EndpointFromEnv("LFRECON_INGEST_KEY", "");
  std::string aggregate_key = svc::EndpointFromEnv("LFRECON_AGGREGATE_KEY", "");
  bool insecure = false;
  svc::ClientSecurity Security(const std::string& endpoint) const {
    svc::SecurityFlags f;
    f.key = key;
    f.server_key = endpoint == ingest ? ingest_key : aggregate_key;
    f.insecure = insecure;
    if (f.key.empty() && f.server_key.empty()) {
      svc::ClientSecurity plain;
      plain.insecure = insecure;
      return plain;
    }
    return svc::ResolveClientSecurity(f);
  }
};

// Turns an error reply into the CLI's errors (exit 1 for input/job problems, 2 for usage).
[[noreturn]] void Rethrow(const svc::ServiceError& e, const std::string& endpoint);
// One request to `endpoint`; ServiceError rethrown as the CLI's errors.
pb::Envelope Call(const Endpoints& e, const std::string& endpoint, const pb::Envelope& req, int timeout_ms);
// --ingest (when `ingest`), --aggregate, --timeout-ms and the key flags.
void AddEndpointFlags(CLI::App* cmd, Endpoints* e, bool ingest);
bool Ended(pb::JobState s);
pb::JobStatus GetStatus(const Endpoints& e, const std::string& job);
// Polls until the job ends (or `timeout_s` passes; InputError); progress at debug level.
pb::JobStatus WaitFor(const Endpoints& e, const std::string& job, double timeout_s);
// One line (or JSON) to stdout; 1 for a FAILED job, else 0.
int PrintStatus(const std::string& job, const pb::JobStatus& s, bool json);

// The options a job may set, as `lfrecon run`'s flags of the same names.
struct JobOptionFlags {
  double voxel_mm = 0, sigma_s = 0;
  bool no_densify = false, all_views = false, no_mask_free_space = false, mask_carving = false;
  bool no_geometric_consistency = false;
  int color_views = 8;
  int max_frame_gap = -1;  // -1: unset (the default)
  std::optional<double> view_step_deg;  // unset: the default
  void AddTo(CLI::App* cmd);
  // Checked as the ingest daemon and `lfrecon run` check them (OptionError: exit 2).
  pb::JobOptions ToProto() const;
};

}  // namespace lfrecon::cli
