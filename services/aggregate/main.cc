// lfrecon-aggregate: fuses dense depth maps into each job's OpenVDB grid,
// leases view tasks to the workers, answers status/export/cancel, and resumes
// jobs from the job store's checkpoint after a restart (aggregator.h).
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <iostream>

#include "aggregator.h"
#include "util/memory.h"
#include "util/error.h"
#include "util/logging.h"

int main(int argc, char** argv) {
  lfrecon::ConfigureHeap();
  using namespace lfrecon::svc;
  CLI::App app{"lfrecon-aggregate: volume aggregator and job coordinator of the lfrecon service"};
  AggregatorOptions o;
  o.endpoint = EndpointFromEnv("LFRECON_AGGREGATE", kDefaultAggregateEndpoint);
  std::string store;
  double max_mb = kDefaultMaxMessageBytes / 1048576.0;
  int verbosity = 0;
  SecurityFlags security;
  AddServerSecurityFlags(&app, &security);
  app.add_option("--bind", o.endpoint, "ZeroMQ endpoint to bind (default: $LFRECON_AGGREGATE or loopback)")->capture_default_str();
  app.add_option("--store", store, "Job store folder (shared with ingest and the workers)")->required();
  app.add_option("--max-message-mb", max_mb, "Largest message accepted or sent, MiB")->capture_default_str();
  app.add_option("--lease-ms", o.lease_ms, "A view task not returned within this is re-issued")->capture_default_str();
  app.add_option("--fusion-delay-ms", o.fusion_delay_ms,
                 "Fault injection (tests): each view's integration holds the grid this much longer");
  app.add_option("--max-task-attempts", o.max_task_attempts,
                 "A view task that failed this many times (worker errors, expired leases) fails its job")
      ->capture_default_str();
  app.add_option("--ingest-timeout-s", o.ingest_timeout_s,
                 "A job still ingesting that has heard nothing from ingest for this long fails")
      ->capture_default_str();
  app.add_option("--max-queued-exports", o.max_queued_exports,
                 "Exports queued per lane (plain, refined); more are refused (ERROR_BUSY)")
      ->capture_default_str();
  app.add_flag("-v,--verbose", verbosity, "More logging");
  CLI11_PARSE(app, argc, argv);
  lfrecon::SetupLogging(verbosity);
  o.store = store;
  o.max_message_bytes = static_cast<std::int64_t>(max_mb * 1048576.0);
  if (o.lease_ms < 1 || o.max_message_bytes < 1024 || o.fusion_delay_ms < 0 || o.max_task_attempts < 1 ||
      !(o.ingest_timeout_s > 0) || o.max_queued_exports < 1) {
    std::cerr << "lfrecon-aggregate: --lease-ms must be >= 1, --max-message-mb >= 0.001, --fusion-delay-ms >= 0, "
                 "--max-task-attempts >= 1 and --ingest-timeout-s > 0\n";
    return 2;
  }
  try {
    o.security = ResolveServerSecurity(security);
    // The endpoint check before the store is opened: a refused endpoint is a usage error.
    CheckServerEndpoint(o.endpoint, o.security);
  } catch (const lfrecon::OptionError& e) {
    std::cerr << "lfrecon-aggregate: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "lfrecon-aggregate: error: " << e.what() << "\n";
    return 1;
  }
  try {
    InstallStopHandlers();
    Aggregator aggregator(o);
    aggregator.Serve();
  } catch (const std::exception& e) {
    std::cerr << "lfrecon-aggregate: error: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
