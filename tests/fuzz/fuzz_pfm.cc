// libFuzzer target: the PFM depth map reader (header tokens, size check, data).
#include <spdlog/spdlog.h>

#include "fuzz_util.h"
#include "io/depth_map_io.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::filesystem::path path = [] {
    spdlog::set_level(spdlog::level::off);
    return lfrecon::fuzz::ScratchDir() / "map.pfm";
  }();
  lfrecon::fuzz::WriteFile(path, std::string(reinterpret_cast<const char*>(data), size));
  try {
    lfrecon::ReadPfm(path);
  } catch (const std::exception& e) {
    lfrecon::fuzz::Refused(e);  // InputError: the reader's answer to a bad file
  }
  return 0;
}
