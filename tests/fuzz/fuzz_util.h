#pragma once
// Helpers of the fuzz targets: the readers under test take paths, so each
// input is written to files in a per-process scratch folder (in /dev/shm when
// there is one). An input for a reader of several files is split at the
// separator line "\n@@\n" (the seed corpora show the layout).
#include <unistd.h>

#include <cstddef>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

namespace lfrecon::fuzz {

inline const std::filesystem::path& ScratchDir() {
  static const std::filesystem::path dir = [] {
    std::error_code ec;
    std::filesystem::path base = std::filesystem::is_directory("/dev/shm", ec) ? std::filesystem::path("/dev/shm")
                                                                               : std::filesystem::temp_directory_path();
    std::filesystem::path d = base / ("lfrecon_fuzz_" + std::to_string(::getpid()));
    std::filesystem::create_directories(d);
    return d;
  }();
  return dir;
}

inline void WriteFile(const std::filesystem::path& path, const std::string& bytes) {
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

// Splits at "\n@@\n" into at most `parts` pieces (the last keeps the rest).
inline std::vector<std::string> Split(const std::uint8_t* data, std::size_t size, std::size_t parts) {
  const std::string all(reinterpret_cast<const char*>(data), size);
  static const std::string sep = "\n@@\n";
  std::vector<std::string> out;
  std::size_t pos = 0;
  while (out.size() + 1 < parts) {
    const std::size_t next = all.find(sep, pos);
    if (next == std::string::npos) break;
    out.push_back(all.substr(pos, next - pos));
    pos = next + sep.size();
  }
  out.push_back(all.substr(pos));
  return out;
}

// A reader's refusal (an exception) is a handled input; with LFRECON_FUZZ_VERBOSE
// set (replaying a corpus) its message is printed, to see what a seed reaches.
inline void Refused(const std::exception& e) {
  static const bool verbose = std::getenv("LFRECON_FUZZ_VERBOSE") != nullptr;
  if (verbose) std::fprintf(stderr, "refused: %s\n", e.what());
}

}  // namespace lfrecon::fuzz
