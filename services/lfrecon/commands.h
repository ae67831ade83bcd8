#pragma once
// Each subcommand registers itself on the root app. Its callback stores the
// exit code in *exit_code; errors are thrown (InputError -> 1, OptionError -> 2)
// and turned into a message and exit code by main().
#include <CLI/CLI.hpp>

namespace lfrecon::cli {

void AddInfoCommand(CLI::App& root, int* exit_code);
void AddSynthCommand(CLI::App& root, int* exit_code);
void AddEvalCommand(CLI::App& root, int* exit_code);
void AddDepthCommand(CLI::App& root, int* exit_code);
void AddRunCommand(CLI::App& root, int* exit_code);
// report: OUT/report.html from a run folder (report_html.cc)
void AddReportCommand(CLI::App& root, int* exit_code);
// poses: COLMAP-driven poses for a video or image folder (poses_command.cc)
void AddPosesCommand(CLI::App& root, int* exit_code);
// submit, status, export, cancel (service_commands.cc)
void AddServiceCommands(CLI::App& root, int* exit_code);
// stream: a client-pushed job (stream_command.cc)
void AddStreamCommand(CLI::App& root, int* exit_code);
// keygen: CURVE key pairs for the service (keygen_command.cc)
void AddKeygenCommand(CLI::App& root, int* exit_code);

}  // namespace lfrecon::cli
