// libFuzzer target: the COLMAP binary reader (cameras.bin, images.bin,
// points3D.bin; the input's three parts, split at "\n@@\n").
#include <spdlog/spdlog.h>

#include "fuzz_util.h"
#include "io/colmap_model.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  namespace fs = std::filesystem;
  static const fs::path dir = [] {
    spdlog::set_level(spdlog::level::off);
    const fs::path d = lfrecon::fuzz::ScratchDir() / "colmap_binary";
    fs::create_directories(d);
    return d;
  }();
  const char* names[] = {"cameras.bin", "images.bin", "points3D.bin"};
  const auto parts = lfrecon::fuzz::Split(data, size, 3);
  for (std::size_t i = 0; i < 3; ++i) {
    if (i < parts.size())
      lfrecon::fuzz::WriteFile(dir / names[i], parts[i]);
    else
      fs::remove(dir / names[i]);
  }
  try {
    lfrecon::ReadColmapModelBinary(dir);
  } catch (const std::exception& e) {
    lfrecon::fuzz::Refused(e);  // InputError: the reader's answer to a bad file
  }
  return 0;
}
