// libFuzzer target: the COLMAP binary reader (cameras.bin, images.bin,
// points3D.bin; the input's three parts, split at "\n@@\n").
#include "folder_reader_harness.h"
#include "io/colmap_model.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return lfrecon::fuzz::FuzzFolderReader<3>("colmap_binary", {"cameras.bin", "images.bin", "points3D.bin"}, data,
                                            size,
                                            [](const std::filesystem::path& d) { lfrecon::ReadColmapModelBinary(d); });
}
