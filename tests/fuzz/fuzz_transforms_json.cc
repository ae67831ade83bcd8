// libFuzzer target: the transforms.json reader (JSON parse with its depth
// limit, intrinsics and pose fields).
#include <spdlog/spdlog.h>

#include "fuzz_util.h"
#include "io/transforms_json.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const std::filesystem::path path = [] {
    spdlog::set_level(spdlog::level::off);
    return lfrecon::fuzz::ScratchDir() / "transforms.json";
  }();
  lfrecon::fuzz::WriteFile(path, std::string(reinterpret_cast<const char*>(data), size));
  try {
    lfrecon::ReadTransformsJson(path);
  } catch (const std::exception& e) {
    lfrecon::fuzz::Refused(e);  // InputError: the reader's answer to a bad file
  }
  return 0;
}
