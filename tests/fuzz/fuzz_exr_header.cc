// libFuzzer target: the OpenEXR header check (ReadExrHeader) that runs before
// OpenCV decodes an EXR depth map. The decoder itself (OpenEXR) is not fuzzed here.
#include <spdlog/spdlog.h>

#include "fuzz_util.h"
#include "io/depth_map_io.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::filesystem::path path = [] {
    spdlog::set_level(spdlog::level::off);
    return lfrecon::fuzz::ScratchDir() / "map.exr";
  }();
  lfrecon::fuzz::WriteFile(path, std::string(reinterpret_cast<const char*>(data), size));
  try {
    lfrecon::ReadExrHeader(path);
  } catch (const std::exception& e) {
    lfrecon::fuzz::Refused(e);  // InputError: the reader's answer to a bad file
  }
  return 0;
}
