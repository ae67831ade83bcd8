#pragma once
// The harness of a fuzz target whose reader takes a folder of files (the COLMAP
// text and binary models): the input's parts, split at "\n@@\n", are written to
// `names` in a scratch subfolder (a file whose part is missing is removed), then
// `read(folder)` runs. An exception from it is the reader's refusal of a bad
// input; anything else (a crash, a sanitizer report) is a finding.
#include <spdlog/spdlog.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <filesystem>

#include "fuzz_util.h"

namespace lfrecon::fuzz {

template <std::size_t N, typename Read>
int FuzzFolderReader(const char* subfolder, const std::array<const char*, N>& names, const std::uint8_t* data,
                     std::size_t size, Read read) {
  namespace fs = std::filesystem;
  static const fs::path dir = [subfolder] {
    spdlog::set_level(spdlog::level::off);
    const fs::path d = ScratchDir() / subfolder;
    fs::create_directories(d);
    return d;
  }();
  const auto parts = Split(data, size, N);
  for (std::size_t i = 0; i < N; ++i) {
    if (i < parts.size())
      WriteFile(dir / names[i], parts[i]);
    else
      fs::remove(dir / names[i]);
  }
  try {
    read(dir);
  } catch (const std::exception& e) {
    Refused(e);  // InputError: the reader's answer to a bad file
  }
  return 0;
}

}  // namespace lfrecon::fuzz
