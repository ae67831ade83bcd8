// lfrecon: reconstruct meshes with thin features from dense light fields.
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <cstdlib>
#include <exception>
#include <iostream>

#include "commands.h"
#include "lfrecon_version.h"
#include "util/memory.h"
#include "util/error.h"
#include "util/logging.h"

int main(int argc, char** argv) {
  lfrecon::ConfigureHeap();
  CLI::App app{"lfrecon: meshes with thin features from dense light fields (Depth from Gradients, 3DV 2016)"};
  app.set_version_flag("--version", std::string("lfrecon ") + LFRECON_VERSION);
  app.require_subcommand(1);
  app.fallthrough();  // -v/-q also after the subcommand
  int verbosity = 0;
  app.add_flag("-v,--verbose", verbosity, "More logging (-v debug, -vv trace)");
  bool quiet = false;
  app.add_flag("-q,--quiet", quiet, "Only warnings and errors");
  app.parse_complete_callback([&] { lfrecon::SetupLogging(quiet ? -1 : verbosity); });

  int exit_code = 0;
  lfrecon::cli::AddInfoCommand(app, &exit_code);
  lfrecon::cli::AddSynthCommand(app, &exit_code);
  lfrecon::cli::AddEvalCommand(app, &exit_code);
  lfrecon::cli::AddDepthCommand(app, &exit_code);
  lfrecon::cli::AddRunCommand(app, &exit_code);
  lfrecon::cli::AddReportCommand(app, &exit_code);
  lfrecon::cli::AddPosesCommand(app, &exit_code);
  lfrecon::cli::AddServiceCommands(app, &exit_code);
  lfrecon::cli::AddStreamCommand(app, &exit_code);
  lfrecon::cli::AddKeygenCommand(app, &exit_code);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    const int code = app.exit(e);  // prints help/version or the usage error
    return code == 0 ? 0 : 2;
  } catch (const lfrecon::OptionError& e) {
    std::cerr << "lfrecon: " << e.what() << "\n";
    return 2;
  } catch (const lfrecon::InputError& e) {
    std::cerr << "lfrecon: error: " << e.what() << "\n";
    return 1;
  } catch (const std::exception& e) {
    std::cerr << "lfrecon: error: " << e.what() << "\n";
    return 1;
  }
  return exit_code;
}
