#pragma once
// The dataset flags every data-reading subcommand shares.
#include <CLI/CLI.hpp>
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

}  // namespace lfrecon::cli
