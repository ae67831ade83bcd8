// libFuzzer target: the PLY reader (ASCII and binary, header element counts).
#include <spdlog/spdlog.h>

#include "fuzz_util.h"
#include "io/ply.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::filesystem::path path = [] {
    spdlog::set_level(spdlog::level::off);
    return lfrecon::fuzz::ScratchDir() / "mesh.ply";
  }();
  lfrecon::fuzz::WriteFile(path, std::string(reinterpret_cast<const char*>(data), size));
  try {
    lfrecon::ReadPly(path);
  } catch (const std::exception& e) {
    lfrecon::fuzz::Refused(e);  // InputError: the reader's answer to a bad file
  }
  return 0;
}
