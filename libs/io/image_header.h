#pragma once
// Image sizes from file headers, for the formats other than PNG and JPEG that
// OpenCV's imread decodes (frame_source.h reads those two): a frame's size is
// checked before any pixel is decoded, whatever its format, so one huge (or
// lying) file cannot make a reader allocate gigabytes.
//   BMP/DIB (BITMAPCOREHEADER and later), TIFF and BigTIFF (the first image
//   file directory: the page OpenCV decodes; every ImageWidth/ImageLength entry
//   in it), WebP (VP8, VP8L, VP8X canvas), PBM/PGM/PPM (P1-P6), PAM (P7), PFM
//   (PF/Pf), Radiance HDR ("-Y H +X W", the only layout OpenCV reads), Sun
//   raster; OpenEXR through ReadExrHeader (depth_map_io.h).
// Anything else (JPEG 2000, GDAL's formats, ...) is refused: its size cannot
// be checked before decoding.
#include <filesystem>
#include <optional>
#include <string>

namespace lfrecon {

struct OtherImageHeader {
  std::string format;         // "bmp", "tiff", "webp", "pnm", "pam", "pfm", "hdr", "sunras"
  long long width = 0, height = 0;  // 0: the format was recognised but its size could not be read
};
// The header of `bytes` (the whole file: a TIFF directory may follow the
// pixels); nullopt when none of the formats above (nor PNG, JPEG, EXR).
std::optional<OtherImageHeader> ReadOtherImageHeader(const std::string& bytes);

// The width and height of image file `file` (its bytes, the whole file) for a
// format other than PNG and JPEG, from its header: OpenEXR by ReadExrHeader,
// the others by ReadOtherImageHeader. Throws InputError naming the file when
// the format is not one of those or its header does not give a size.
std::pair<long long, long long> OtherImageSize(const std::filesystem::path& file, const std::string& bytes);

// The width and height of any image file this reads (PNG, JPEG and the
// formats above) from its header, without decoding it (a PNG or JPEG from its
// first 1 MiB, other files read whole); InputError naming the file when it
// cannot be opened or as OtherImageSize.
std::pair<long long, long long> ImageFileHeaderSize(const std::filesystem::path& file);

}  // namespace lfrecon
