#include "io/frame_source.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <cstdio>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>

#include "io/depth_map_io.h"
#include "util/error.h"

namespace lfrecon {
namespace fs = std::filesystem;

namespace {

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return std::tolower(c); });
  return s;
}

bool IsImageExtension(const fs::path& path) {
  const std::string ext = Lower(path.extension().string());
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

cv::Mat ReadImageFloat(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw InputError(path.string(), "image file does not exist");
  if (Lower(path.extension().string()) == ".exr") EnableOpenCvExr();
  cv::Mat raw;
  try {
    // IMREAD_UNCHANGED: keep 16-bit data and ignore EXIF orientation, as COLMAP does,
    // so that image sizes agree with the cameras.
    raw = cv::imread(path.string(), cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    throw InputError(path.string(), std::string("image cannot be decoded: ") + e.what());
  }
  if (raw.empty()) throw InputError(path.string(), "image cannot be read (corrupt or unsupported format)");
  try {
    return ToFloatBgr(raw);
  } catch (const std::invalid_argument& e) {
    throw InputError(path.string(), e.what());
  }
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
  const std::string ext = Lower(path.extension().string());
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
  frame.image = ReadImageFloat(folder_ / names_[index]);
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
