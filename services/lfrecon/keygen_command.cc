// `lfrecon keygen`: a CURVE key pair for a daemon, worker or client of the
// streaming service (common/auth.h): NAME.key (secret, mode 0600) and NAME.pub
// (an allow-list line with the key's role).
#include <spdlog/spdlog.h>

#include <filesystem>
#include <iostream>

#include "commands.h"
#include "common/auth.h"
#include "util/error.h"

namespace lfrecon::cli {

void AddKeygenCommand(CLI::App& root, int* exit_code) {
  struct Args {
    std::string name, role = "client";
    std::filesystem::path out = ".";
    bool force = false;
  };
  auto a = std::make_shared<Args>();
  auto* cmd = root.add_subcommand(
      "keygen", "CURVE key pair for the streaming service: OUT/NAME.key (secret, 0600) and OUT/NAME.pub (allow-list line)");
  cmd->add_option("name", a->name, "Key name (file names, and the name daemons log)")->required();
  cmd->add_option("--role", a->role, "What the key may do: client (submit, status, export, cancel), worker "
                                     "(tasks), ingest (the ingest daemon), server (a daemon's own key)")
      ->capture_default_str()
      ->check(CLI::IsMember({"client", "worker", "ingest", "server"}));
  cmd->add_option("-o,--out", a->out, "Folder of the key files")->capture_default_str();
  cmd->add_flag("--force", a->force, "Replace existing key files");
  cmd->callback([a, exit_code] {
    if (!svc::HasCurve()) throw InputError("libzmq", "this libzmq has no CURVE support");
    const svc::CurveKeyPair keys = svc::GenerateKeyPair();
    const auto [key, pub] = svc::WriteKeyFiles(a->out, a->name, *svc::ParseRole(a->role), keys, a->force);
    std::cout << "wrote " << key.string() << " (secret, mode 0600) and " << pub.string() << "\n"
              << a->role << " " << keys.public_key << " " << a->name << "\n";
    *exit_code = 0;
  });
}

}  // namespace lfrecon::cli
