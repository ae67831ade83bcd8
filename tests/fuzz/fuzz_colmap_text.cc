// libFuzzer target: the COLMAP text reader (cameras.txt, images.txt,
// points3D.txt; the input's three parts, split at "\n@@\n").
#include "folder_reader_harness.h"
#include "io/colmap_model.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  return lfrecon::fuzz::FuzzFolderReader<3>("colmap_text", {"cameras.txt", "images.txt", "points3D.txt"}, data, size,
                                            [](const std::filesystem::path& d) { lfrecon::ReadColmapModelText(d); });
}
