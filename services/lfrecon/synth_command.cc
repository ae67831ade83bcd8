#include "commands.h"

namespace lfrecon::cli {
void AddSynthCommand(CLI::App& root, int* exit_code) {}
}  // namespace lfrecon::cli
