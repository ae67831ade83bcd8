#include "io/frame_source.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "io/depth_map_io.h"
#include "io/file_bytes.h"
#include "io/image_header.h"
#include "util/error.h"
#include "util/path.h"

namespace lfrecon {
namespace fs = std::filesystem;

namespace {

bool IsImageExtension(const fs::path& path) {
  const std::string ext = LowerExtension(path);
  return ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".tif" || ext == ".tiff" ||
         ext == ".exr" || ext == ".bmp";
}

}  // namespace

bool NaturalNameLess(const std::string& a, const std::string& b) {
  size_t i = 0, j = 0;
  while (i < a.size() && j < b.size()) {
    const bool da = std::isdigit(static_cast<unsigned char>(a[i])),
               db = std::isdigit(static_cast<unsigned char>(b[j]));
    if (da && db) {
      // Compare digit runs by value: skip leading zeros, then longer is larger, then lexically.
      size_t ei = i, ej = j;
      while (ei < a.size() && std::isdigit(static_cast<unsigned char>(a[ei]))) ++ei;
      while (ej < b.size() && std::isdigit(static_cast<unsigned char>(b[ej]))) ++ej;
      size_t si = i, sj = j;
      while (si + 1 < ei && a[si] == '0') ++si;
      while (sj + 1 < ej && b[sj] == '0') ++sj;
      if (ei - si != ej - sj) return ei - si < ej - sj;
      const int c = a.compare(si, ei - si, b, sj, ej - sj);
      if (c != 0) return c < 0;
      i = ei;
      j = ej;
    } else {
      if (a[i] != b[j]) return static_cast<unsigned char>(a[i]) < static_cast<unsigned char>(b[j]);
      ++i;
      ++j;
    }
  }
  if (a.size() - i != b.size() - j) return a.size() - i < b.size() - j;
  return a < b;  // equal by value ("01" vs "1"): fall back to a strict order
}

cv::Mat ToFloatBgr(const cv::Mat& image) {
  if (image.empty()) return cv::Mat();
  double scale = 1.0;
  switch (image.depth()) {
    case CV_8U: scale = 1.0 / 255.0; break;
    case CV_16U: scale = 1.0 / 65535.0; break;
    case CV_32F:
    case CV_64F: scale = 1.0; break;
    default:
      throw std::invalid_argument("ToFloatBgr: unsupported pixel depth " + std::to_string(image.depth()));
  }
  cv::Mat f;
  image.convertTo(f, CV_32F, scale);
  cv::Mat out;
  switch (f.channels()) {
    case 1: cv::cvtColor(f, out, cv::COLOR_GRAY2BGR); break;
    case 3: out = f; break;
    case 4: cv::cvtColor(f, out, cv::COLOR_BGRA2BGR); break;
    default:
      throw std::invalid_argument("ToFloatBgr: unsupported channel count " + std::to_string(f.channels()));
  }
  return out;
}

cv::Mat CompactFrame(const cv::Mat& frame) {
  if (frame.type() != CV_32FC3) return frame;
  cv::Mat u8;
  frame.convertTo(u8, CV_8U, 255.0);
  const cv::Mat back = ToFloatBgr(u8);
  const std::size_t row_bytes = static_cast<std::size_t>(frame.cols) * frame.elemSize();
  for (int r = 0; r < frame.rows; ++r)
    if (std::memcmp(back.ptr(r), frame.ptr(r), row_bytes) != 0) return frame;
  return u8;
}

cv::Mat ExpandFrame(const cv::Mat& pixels) { return pixels.depth() == CV_8U ? ToFloatBgr(pixels) : pixels; }

namespace {

int Be16(const std::string& b, std::size_t at) {
  return (static_cast<unsigned char>(b[at]) << 8) | static_cast<unsigned char>(b[at + 1]);
}

std::optional<ImageHeader> ReadPngHeader(const std::string& b) {
  // Signature, then the IHDR chunk: length, "IHDR", width and height (big-endian).
  static const char kSignature[] = "\x89PNG\r\n\x1a\n";
  if (b.size() < 24 || b.compare(0, 8, kSignature, 8) != 0 || b.compare(12, 4, "IHDR") != 0) return std::nullopt;
  auto be32 = [&](std::size_t at) {
    return (std::uint32_t{static_cast<unsigned char>(b[at])} << 24) | (std::uint32_t(Be16(b, at + 1)) << 8) |
           static_cast<unsigned char>(b[at + 3]);
  };
  ImageHeader h;
  h.format = "png";
  const std::uint32_t w = be32(16), hh = be32(20);
  h.width = static_cast<int>(std::min<std::uint32_t>(w, 1u << 30));
  h.height = static_cast<int>(std::min<std::uint32_t>(hh, 1u << 30));
  return h;
}

std::optional<ImageHeader> ReadJpegHeader(const std::string& b) {
  const std::size_t n = b.size();
  if (n < 4 || static_cast<unsigned char>(b[0]) != 0xFF || static_cast<unsigned char>(b[1]) != 0xD8)
    return std::nullopt;
  ImageHeader h;
  h.format = "jpeg";
  h.complete = false;
  auto at = [&](std::size_t i) { return static_cast<unsigned char>(b[i]); };
  std::size_t pos = 2;
  while (pos < n) {
    if (at(pos) != 0xFF) return h;  // not at a marker: corrupt
    while (pos < n && at(pos) == 0xFF) ++pos;  // fill bytes
    if (pos >= n) return h;
    const unsigned char m = at(pos++);
    if (m == 0xD9) {  // EOI
      h.complete = true;
      return h;
    }
    if (m == 0x01 || (m >= 0xD0 && m <= 0xD7)) continue;  // no length
    if (pos + 2 > n) return h;
    const std::size_t length = static_cast<std::size_t>(Be16(b, pos));
    if (length < 2 || pos + length > n) return h;
    const bool sof = m >= 0xC0 && m <= 0xCF && m != 0xC4 && m != 0xC8 && m != 0xCC;
    if (sof && length >= 7 && h.width == 0) {
      h.height = Be16(b, pos + 3);
      h.width = Be16(b, pos + 5);
    }
    pos += length;
    if (m == 0xDA) {  // start of scan: entropy-coded data up to the next marker
      while (pos + 1 < n) {
        if (at(pos) != 0xFF) {
          ++pos;
        } else if (at(pos + 1) == 0x00 || (at(pos + 1) >= 0xD0 && at(pos + 1) <= 0xD7)) {
          pos += 2;  // stuffed 0xFF or a restart marker
        } else if (at(pos + 1) == 0xFF) {
          ++pos;
        } else {
          break;
        }
      }
      if (pos + 1 >= n) return h;  // the data ends inside a scan: truncated
    }
  }
  return h;
}

}  // namespace

std::optional<ImageHeader> ReadImageHeader(const std::string& bytes) {
  if (auto h = ReadPngHeader(bytes)) return h;
  return ReadJpegHeader(bytes);
}

namespace {

void CheckImageSize(const std::string& file, int width, int height, const char* what, std::optional<cv::Size> expect) {
  if (expect && (width != expect->width || height != expect->height))
    throw InputError(file, std::string(what) + " is " + std::to_string(width) + "x" + std::to_string(height) +
                               " but its camera is " + std::to_string(expect->width) + "x" +
                               std::to_string(expect->height));
  if (static_cast<std::int64_t>(width) * height > kMaxImagePixels)
    throw InputError(file, std::string(what) + " is " + std::to_string(width) + "x" + std::to_string(height) +
                               ": more than the " + std::to_string(kMaxImagePixels) + " pixels a frame may have");
}

// The header check before decoding (PNG/JPEG): size, JPEG completeness.
void CheckImageHeader(const std::string& file, const ImageHeader& header, std::optional<cv::Size> expect) {
  if (!header.complete)
    throw InputError(file, "JPEG data ends before its end-of-image marker (truncated or corrupt file)");
  if (header.width > 0 || header.format == "png") CheckImageSize(file, header.width, header.height, "image header", expect);
}

// EXIF orientation is ignored, as COLMAP does: its Bitmap::Read opens images
// with OpenImageIO's "oiio:reorient" = 0 (src/colmap/sensor/bitmap.cc; FreeImage
// in older versions did not rotate either), so its cameras and poses describe
// the pixels as stored. IMREAD_UNCHANGED (keeps 16-bit data) already skips
// OpenCV's EXIF rotation; IMREAD_IGNORE_ORIENTATION says so explicitly.
constexpr int kImreadFlags = cv::IMREAD_UNCHANGED | cv::IMREAD_IGNORE_ORIENTATION;

cv::Mat FinishDecoded(const std::string& file, const cv::Mat& raw, std::optional<cv::Size> expect) {
  if (raw.empty()) throw InputError(file, "image cannot be read (corrupt or unsupported format)");
  CheckImageSize(file, raw.cols, raw.rows, "image", expect);
  try {
    return ToFloatBgr(raw);
  } catch (const std::invalid_argument& e) {
    throw InputError(file, e.what());
  }
}

}  // namespace

cv::Mat DecodeImageFloat(const std::string& bytes, const std::string& what, std::optional<cv::Size> expect) {
  const auto header = ReadImageHeader(bytes);
  if (!header) throw InputError(what, "not PNG or JPEG data");
  if (bytes.size() > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw InputError(what, "image data larger than 2 GiB");
  CheckImageHeader(what, *header, expect);
  cv::Mat raw;
  try {
    raw = cv::imdecode(cv::Mat(1, static_cast<int>(bytes.size()), CV_8U, const_cast<char*>(bytes.data())), kImreadFlags);
  } catch (const cv::Exception& e) {
    throw InputError(what, std::string("image cannot be decoded: ") + e.what());
  }
  return FinishDecoded(what, raw, expect);
}

cv::Mat ReadImageFloat(const fs::path& path, std::optional<cv::Size> expect) {
  const std::string file = path.string();
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw InputError(file, "image file does not exist");
  if (LowerExtension(path) == ".exr") EnableOpenCvExr();
  // cv::imdecode takes the bytes' count as an int.
  std::string bytes = ReadFileBytes(path, static_cast<std::uintmax_t>(std::numeric_limits<int>::max()));
  // PNG/JPEG from the bytes read; other formats from the file (some OpenCV decoders read files only).
  if (ReadImageHeader(bytes)) return DecodeImageFloat(bytes, file, expect);
  // Any other format: its size from its header too, before a pixel is decoded
  // (image_header.h); a format whose header cannot be read is refused.
  {
    const auto [width, height] = OtherImageSize(path, bytes);
    auto to_int = [](long long v) { return static_cast<int>(std::min<long long>(v, std::numeric_limits<int>::max())); };
    CheckImageSize(file, to_int(width), to_int(height), "image header", expect);
  }
  bytes = std::string();
  cv::Mat raw;
  try {
    raw = cv::imread(file, kImreadFlags);
  } catch (const cv::Exception& e) {
    throw InputError(file, std::string("image cannot be decoded: ") + e.what());
  }
  return FinishDecoded(file, raw, expect);
}

void WriteImageFloat(const fs::path& path, const cv::Mat& image, int jpeg_quality) {
  if (image.empty()) throw InputError(path.string(), "refusing to write an empty image");
  cv::Mat out;
  if (image.depth() == CV_32F || image.depth() == CV_64F) {
    image.convertTo(out, CV_8U, 255.0);  // saturates outside [0, 1]
  } else {
    out = image;
  }
  std::vector<int> params;
  const std::string ext = LowerExtension(path);
  if (ext == ".jpg" || ext == ".jpeg") params = {cv::IMWRITE_JPEG_QUALITY, jpeg_quality};
  bool ok = false;
  try {
    ok = cv::imwrite(path.string(), out, params);
  } catch (const cv::Exception& e) {
    throw InputError(path.string(), std::string("cannot write image: ") + e.what());
  }
  if (!ok) throw InputError(path.string(), "cannot write image");
}

// ---------------------------------------------------------------------------

ImageFolderSource::ImageFolderSource(fs::path folder, std::vector<std::string> names)
    : folder_(std::move(folder)), names_(std::move(names)) {}

std::unique_ptr<ImageFolderSource> ImageFolderSource::FromFolder(const fs::path& folder) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) throw InputError(folder.string(), "image folder does not exist");
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(folder, ec)) {
    if (entry.is_regular_file() && IsImageExtension(entry.path()))
      names.push_back(entry.path().filename().string());
  }
  if (ec) throw InputError(folder.string(), "cannot list folder: " + ec.message());
  std::sort(names.begin(), names.end(), NaturalNameLess);
  return std::make_unique<ImageFolderSource>(folder, std::move(names));
}

bool ImageFolderSource::Next(Frame* frame) {
  if (next_ >= NumFrames()) return false;
  *frame = Read(next_);
  ++next_;
  return true;
}

Frame ImageFolderSource::Read(int index) {
  if (index < 0 || index >= NumFrames())
    throw InputError(folder_.string(), "frame index " + std::to_string(index) + " out of range [0, " +
                                           std::to_string(NumFrames()) + ")");
  Frame frame;
  frame.index = index;
  frame.name = names_[index];
  frame.image = ReadImageFloat(folder_ / names_[index],
                               sizes_.empty() ? std::nullopt : std::optional<cv::Size>(sizes_.at(index)));
  return frame;
}

// ---------------------------------------------------------------------------

struct VideoSource::Impl {
  fs::path path;
  cv::VideoCapture capture;
  int num_frames = 0;
  int next = 0;  // index of the frame the next capture.read() returns
};

VideoSource::VideoSource(const fs::path& path) : impl_(std::make_unique<Impl>()) {
  impl_->path = path;
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw InputError(path.string(), "video file does not exist");
  try {
    impl_->capture.open(path.string());
  } catch (const cv::Exception& e) {
    throw InputError(path.string(), std::string("cannot open video: ") + e.what());
  }
  if (!impl_->capture.isOpened())
    throw InputError(path.string(), "cannot open video (corrupt or unsupported codec)");
  const double count = impl_->capture.get(cv::CAP_PROP_FRAME_COUNT);
  impl_->num_frames = count > 0 && count < 1e9 ? static_cast<int>(count) : 0;
}

VideoSource::~VideoSource() = default;

int VideoSource::NumFrames() const { return impl_->num_frames; }

bool VideoSource::Next(Frame* frame) {
  cv::Mat raw;
  bool ok = false;
  try {
    ok = impl_->capture.read(raw);
  } catch (const cv::Exception& e) {
    throw InputError(impl_->path.string(), "frame " + std::to_string(impl_->next),
                     std::string("cannot decode: ") + e.what());
  }
  if (!ok || raw.empty()) {
    if (impl_->num_frames > 0 && impl_->next < impl_->num_frames - 1)
      spdlog::warn("{}: video ended at frame {} although its header announces {}", impl_->path.string(),
                   impl_->next, impl_->num_frames);
    return false;
  }
  char name[32];
  std::snprintf(name, sizeof(name), "frame_%05d", impl_->next);
  frame->index = impl_->next;
  frame->name = name;
  try {
    frame->image = ToFloatBgr(raw);
  } catch (const std::invalid_argument& e) {
    throw InputError(impl_->path.string(), "frame " + std::to_string(impl_->next), e.what());
  }
  ++impl_->next;
  return true;
}

Frame VideoSource::Read(int index) {
  if (index < 0 || (impl_->num_frames > 0 && index >= impl_->num_frames))
    throw InputError(impl_->path.string(), "frame index " + std::to_string(index) + " out of range [0, " +
                                               std::to_string(impl_->num_frames) + ")");
  if (index != impl_->next) {
    if (!impl_->capture.set(cv::CAP_PROP_POS_FRAMES, index))
      throw InputError(impl_->path.string(), "cannot seek to frame " + std::to_string(index));
    impl_->next = index;
  }
  Frame frame;
  if (!Next(&frame)) throw InputError(impl_->path.string(), "cannot read frame " + std::to_string(index));
  return frame;
}

}  // namespace lfrecon
