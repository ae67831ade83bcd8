#pragma once
// spdlog set-up shared by the CLI, services and tests. Logs go to stderr so
// stdout stays clean for machine-readable output (--json).
namespace lfrecon {

// verbosity: -1 quiet (warnings and errors), 0 info, 1 debug, 2 trace.
void SetupLogging(int verbosity);

}  // namespace lfrecon
