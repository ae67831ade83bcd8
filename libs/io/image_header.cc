#include "image_header.h"

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>

#include "io/depth_map_io.h"
#include "io/file_bytes.h"
#include "io/frame_source.h"
#include "util/error.h"

namespace lfrecon {
namespace {

constexpr long long kMaxSide = 1ll << 31;  // any side beyond this is refused by the pixel cap anyway

unsigned char At(const std::string& b, std::size_t i) { return static_cast<unsigned char>(b[i]); }

// Unsigned little- or big-endian integers of `n` bytes at `at`; 0 when out of the data.
std::uint64_t Read(const std::string& b, std::size_t at, int n, bool little) {
  if (at > b.size() || b.size() - at < static_cast<std::size_t>(n)) return 0;
  std::uint64_t v = 0;
  for (int i = 0; i < n; ++i) {
    const std::uint64_t byte = At(b, at + (little ? n - 1 - i : i));
    v = (v << 8) | byte;
  }
  return v;
}

long long Clamp(long long v) { return std::min(std::max(v, 0ll), kMaxSide); }

std::optional<OtherImageHeader> Bmp(const std::string& b) {
  if (b.size() < 2 || b.compare(0, 2, "BM") != 0) return std::nullopt;
  OtherImageHeader h{"bmp"};
  const std::uint64_t dib = Read(b, 14, 4, true);
  if (dib == 12) {  // BITMAPCOREHEADER: 16-bit sizes
    h.width = static_cast<long long>(Read(b, 18, 2, true));
    h.height = static_cast<long long>(Read(b, 20, 2, true));
  } else if (dib >= 40 && b.size() >= 26) {  // BITMAPINFOHEADER and later: signed 32-bit, height < 0 top-down
    h.width = static_cast<std::int32_t>(Read(b, 18, 4, true));
    const long long height = static_cast<std::int32_t>(Read(b, 22, 4, true));
    h.height = height < 0 ? -height : height;
    if (h.width < 0) h.width = kMaxSide;  // nonsense: refused
  }
  h.width = Clamp(h.width);
  h.height = Clamp(h.height);
  return h;
}

// The first image file directory: the largest ImageWidth (256) and ImageLength
// (257) it lists (a directory may repeat a tag; the largest is what is checked).
std::optional<OtherImageHeader> Tiff(const std::string& b) {
  if (b.size() < 8) return std::nullopt;
  const bool little = b.compare(0, 2, "II") == 0;
  if (!little && b.compare(0, 2, "MM") != 0) return std::nullopt;
  const std::uint64_t version = Read(b, 2, 2, little);
  if (version != 42 && version != 43) return std::nullopt;
  OtherImageHeader h{"tiff"};
  const bool big = version == 43;  // BigTIFF: 8-byte offsets and counts, 20-byte entries
  const std::uint64_t ifd = big ? Read(b, 8, 8, little) : Read(b, 4, 4, little);
  if (ifd < 8 || ifd >= b.size()) return h;
  const std::uint64_t count = Read(b, ifd, big ? 8 : 2, little);
  const std::size_t first = ifd + (big ? 8 : 2), entry = big ? 20 : 12;
  if (count == 0 || count > (b.size() - std::min<std::size_t>(first, b.size())) / entry) return h;
  long long width = 0, height = 0;
  for (std::uint64_t i = 0; i < count; ++i) {
    const std::size_t e = first + i * entry;
    const std::uint64_t tag = Read(b, e, 2, little), type = Read(b, e + 2, 2, little);
    if (tag != 256 && tag != 257) continue;
    const std::size_t value = e + (big ? 12 : 8);
    long long v;
    if (type == 3) v = static_cast<long long>(Read(b, value, 2, little));  // SHORT
    else if (type == 4) v = static_cast<long long>(Read(b, value, 4, little));  // LONG
    else if (type == 16 && big) v = static_cast<long long>(std::min<std::uint64_t>(Read(b, value, 8, little), kMaxSide));
    else v = kMaxSide;  // a type libtiff would not take for a size: refused
    (tag == 256 ? width : height) = std::max(tag == 256 ? width : height, Clamp(v));
  }
  h.width = width;
  h.height = height;
  if (width == 0 || height == 0) h.width = h.height = 0;
  return h;
}

std::optional<OtherImageHeader> Webp(const std::string& b) {
  if (b.size() < 16 || b.compare(0, 4, "RIFF") != 0 || b.compare(8, 4, "WEBP") != 0) return std::nullopt;
  OtherImageHeader h{"webp"};
  const std::string chunk = b.substr(12, 4);
  if (chunk == "VP8 " && b.size() >= 30 && At(b, 23) == 0x9d && At(b, 24) == 0x01 && At(b, 25) == 0x2a) {
    h.width = static_cast<long long>(Read(b, 26, 2, true) & 0x3fff);
    h.height = static_cast<long long>(Read(b, 28, 2, true) & 0x3fff);
  } else if (chunk == "VP8L" && b.size() >= 25 && At(b, 20) == 0x2f) {
    const std::uint64_t bits = Read(b, 21, 4, true);
    h.width = static_cast<long long>(bits & 0x3fff) + 1;
    h.height = static_cast<long long>((bits >> 14) & 0x3fff) + 1;
  } else if (chunk == "VP8X" && b.size() >= 30) {
    h.width = static_cast<long long>(Read(b, 24, 3, true)) + 1;
    h.height = static_cast<long long>(Read(b, 27, 3, true)) + 1;
  }
  return h;
}

// Netpbm: numbers after the magic, separated by white space and '#' comments.
class PnmText {
 public:
  PnmText(const std::string& b, std::size_t pos) : b_(b), pos_(pos) {}
  // The next decimal number; -1 when there is none.
  long long Number() {
    Skip();
    if (pos_ >= b_.size() || !std::isdigit(At(b_, pos_))) return -1;
    long long v = 0;
    while (pos_ < b_.size() && std::isdigit(At(b_, pos_))) v = std::min(v * 10 + (At(b_, pos_++) - '0'), kMaxSide);
    return v;
  }
  // The next word (PAM header tokens).
  std::string Word() {
    Skip();
    std::string w;
    while (pos_ < b_.size() && !std::isspace(At(b_, pos_)) && w.size() < 64) w += b_[pos_++];
    return w;
  }

 private:
  void Skip() {
    while (pos_ < b_.size()) {
      if (std::isspace(At(b_, pos_))) {
        ++pos_;
      } else if (b_[pos_] == '#') {
        while (pos_ < b_.size() && b_[pos_] != '\n' && b_[pos_] != '\r') ++pos_;
      } else {
        break;
      }
    }
  }
  const std::string& b_;
  std::size_t pos_;
};

std::optional<OtherImageHeader> Pnm(const std::string& b) {
  if (b.size() < 3 || b[0] != 'P' || !std::isspace(At(b, 2))) return std::nullopt;
  const char kind = b[1];
  OtherImageHeader h;
  if (kind >= '1' && kind <= '6') {
    h.format = "pnm";
    PnmText t(b, 2);
    h.width = t.Number();
    h.height = t.Number();
  } else if (kind == 'F' || kind == 'f') {
    h.format = "pfm";
    PnmText t(b, 2);
    h.width = t.Number();
    h.height = t.Number();
  } else if (kind == '7') {
    h.format = "pam";
    PnmText t(b, 2);
    for (int i = 0; i < 64; ++i) {  // WIDTH w, HEIGHT h, DEPTH, MAXVAL, TUPLTYPE ..., ENDHDR
      const std::string w = t.Word();
      if (w.empty() || w == "ENDHDR") break;
      if (w == "WIDTH") h.width = t.Number();
      else if (w == "HEIGHT") h.height = t.Number();
    }
  } else {
    return std::nullopt;
  }
  if (h.width <= 0 || h.height <= 0) h.width = h.height = 0;
  return h;
}

// Radiance: "#?RADIANCE" (or "#?RGBE"), header lines, an empty line, then the
// resolution line; OpenCV reads only "-Y <height> +X <width>".
std::optional<OtherImageHeader> Hdr(const std::string& b) {
  if (b.compare(0, 10, "#?RADIANCE") != 0 && b.compare(0, 6, "#?RGBE") != 0) return std::nullopt;
  OtherImageHeader h{"hdr"};
  const std::size_t blank = b.find("\n\n", 0);
  if (blank == std::string::npos || blank > (1u << 20)) return h;
  const std::size_t start = blank + 2, end = b.find('\n', start);
  const std::string line = b.substr(start, std::min<std::size_t>(end == std::string::npos ? 64 : end - start, 64));
  long long height = -1, width = -1;
  char rest = 0;
  if (std::sscanf(line.c_str(), "-Y %lld +X %lld%c", &height, &width, &rest) >= 2 && height > 0 && width > 0) {
    h.width = Clamp(width);
    h.height = Clamp(height);
  }
  return h;
}

std::optional<OtherImageHeader> SunRaster(const std::string& b) {
  if (b.size() < 4 || Read(b, 0, 4, false) != 0x59a66a95u) return std::nullopt;
  OtherImageHeader h{"sunras"};
  h.width = Clamp(static_cast<long long>(Read(b, 4, 4, false)));
  h.height = Clamp(static_cast<long long>(Read(b, 8, 4, false)));
  return h;
}

bool IsExr(const std::string& b) { return b.size() >= 4 && Read(b, 0, 4, true) == 20000630u; }

}  // namespace

std::optional<OtherImageHeader> ReadOtherImageHeader(const std::string& bytes) {
  for (auto* reader : {Bmp, Tiff, Webp, Pnm, Hdr, SunRaster})
    if (auto h = reader(bytes)) return h;
  return std::nullopt;
}

std::pair<long long, long long> OtherImageSize(const std::filesystem::path& file, const std::string& bytes) {
  if (IsExr(bytes)) {
    const ExrHeader h = ReadExrHeader(file);  // InputError naming the file beyond its own bounds
    return {h.width, h.height};
  }
  const auto h = ReadOtherImageHeader(bytes);
  if (!h)
    throw InputError(file.string(),
                     "unrecognised image format: its size cannot be checked before decoding (PNG, JPEG, TIFF, BMP, "
                     "WebP, OpenEXR, PNM/PAM/PFM, Radiance HDR and Sun raster images are read)");
  if (h->width <= 0 || h->height <= 0)
    throw InputError(file.string(), "the " + h->format + " header gives no image size (corrupt or truncated file)");
  return {h->width, h->height};
}

std::pair<long long, long long> ImageFileHeaderSize(const std::filesystem::path& file) {
  {
    // The first 1 MiB holds any PNG's header and any JPEG's frame header after its EXIF data.
    std::ifstream in(file, std::ios::binary);
    if (!in) throw InputError(file.string(), "cannot open image file");
    std::string head(std::size_t{1} << 20, '\0');
    in.read(head.data(), static_cast<std::streamsize>(head.size()));
    head.resize(static_cast<std::size_t>(in.gcount()));
    if (const auto h = ReadImageHeader(head); h && h->width > 0 && h->height > 0) return {h->width, h->height};
  }
  // Whole: a JPEG whose frame header lies beyond 1 MiB, or another format (a TIFF's directory may follow its pixels).
  const std::string bytes = ReadFileBytes(file);
  if (const auto h = ReadImageHeader(bytes)) {
    if (h->width <= 0 || h->height <= 0)
      throw InputError(file.string(), "the " + h->format + " header gives no image size");
    return {h->width, h->height};
  }
  return OtherImageSize(file, bytes);
}

}  // namespace lfrecon
