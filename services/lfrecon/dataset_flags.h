#pragma once
// The dataset flags every data-reading subcommand shares.
#include <CLI/CLI.hpp>
#include <string>
#include <vector>

#include "io/dataset.h"

namespace lfrecon::cli {

struct DatasetFlags {
  DatasetOptions options;
  std::vector<double> bbox;  // 6 numbers when given
  void AddTo(CLI::App* app);
  // Fills options.bbox from the flag; throws OptionError if malformed.
  DatasetOptions Resolve() const;
};

// "A:B:STEP", "A:B" or "A" (0-based, B exclusive) -> view indices within
// [0, n); all views when `spec` is empty. Throws OptionError naming --views.
std::vector<int> ParseViewRange(const std::string& spec, int n);

}  // namespace lfrecon::cli
