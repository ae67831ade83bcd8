#include "io/depth_map_io.h"

#include <algorithm>
#include <vector>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <string>

#include "io/file_bytes.h"
#include "io/input_text.h"
#include "util/error.h"
#include "util/path.h"

namespace lfrecon {
namespace fs = std::filesystem;

namespace {

cv::Mat ToFloat32(const cv::Mat& map) {
  cv::Mat f;
  if (map.depth() == CV_32F)
    f = map;
  else
    map.convertTo(f, CV_32F);
  return f.isContinuous() ? f : f.clone();
}

}  // namespace

void EnableOpenCvExr() {
  // A function-local static runs once, thread-safely, before the first EXR call.
  static const bool enabled = [] {
    setenv("OPENCV_IO_ENABLE_OPENEXR", "1", 1);
    return true;
  }();
  (void)enabled;
}

// ---------------------------------------------------------------------------
// PFM

void WritePfm(const fs::path& path, const cv::Mat& map) {
  if (map.empty()) throw InputError(path.string(), "refusing to write an empty map");
  if (map.channels() != 1 && map.channels() != 3)
    throw InputError(path.string(), "PFM holds 1 or 3 channels, got " + std::to_string(map.channels()));
  cv::Mat f = ToFloat32(map);
  if (f.channels() == 3) {
    cv::Mat rgb;
    cv::cvtColor(f, rgb, cv::COLOR_BGR2RGB);  // PFM colour is RGB
    f = rgb;
  }
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw InputError(path.string(), "cannot open file for writing");
  out << (f.channels() == 1 ? "Pf" : "PF") << "\n"
      << f.cols << " " << f.rows << "\n-1\n";  // -1: little-endian
  const size_t row_bytes = sizeof(float) * f.cols * f.channels();
  for (int r = f.rows - 1; r >= 0; --r) out.write(f.ptr<char>(r), static_cast<std::streamsize>(row_bytes));
  out.close();
  if (!out) throw InputError(path.string(), "write failed");
}

cv::Mat ReadPfm(const fs::path& path) {
  const std::string file = path.string();
  const std::string data = ReadFileBytes(path);
  // Header: three whitespace-separated tokens after the magic, then one whitespace byte.
  size_t pos = 0;
  auto token = [&](const char* what) {
    while (pos < data.size() && std::isspace(static_cast<unsigned char>(data[pos]))) ++pos;
    const size_t start = pos;
    while (pos < data.size() && !std::isspace(static_cast<unsigned char>(data[pos]))) ++pos;
    if (start == pos || pos >= data.size()) throw InputError(file, what, "PFM header is truncated");
    return data.substr(start, pos - start);
  };
  const std::string magic = token("magic");
  int channels = 0;
  if (magic == "Pf")
    channels = 1;
  else if (magic == "PF")
    channels = 3;
  else
    throw InputError(file, "magic", "not a PFM file (expected 'Pf' or 'PF', got " + InputToken(magic) + ")");
  auto integer = [&](const char* what) {
    const std::string t = token(what);
    char* end = nullptr;
    const long v = std::strtol(t.c_str(), &end, 10);
    if (*end != '\0' || v <= 0 || v > (1 << 20)) throw InputError(file, what, "invalid value " + InputToken(t));
    return static_cast<int>(v);
  };
  const int width = integer("width");
  const int height = integer("height");
  const std::string scale_text = token("scale");
  char* end = nullptr;
  const double scale = std::strtod(scale_text.c_str(), &end);
  if (*end != '\0' || scale == 0 || !std::isfinite(scale))
    throw InputError(file, "scale", "invalid value " + InputToken(scale_text));
  ++pos;  // the single whitespace byte that ends the header
  const bool little_endian = scale < 0;
  const std::uint64_t row_bytes = sizeof(float) * static_cast<std::uint64_t>(width) * channels;
  const std::uint64_t need = row_bytes * static_cast<std::uint64_t>(height);
  if (data.size() < pos || data.size() - pos < need)
    throw InputError(file, "data",
                     "file is truncated: " + std::to_string(width) + "x" + std::to_string(height) +
                         " needs " + std::to_string(need) + " bytes, " +
                         std::to_string(data.size() - std::min(pos, data.size())) + " present");
  cv::Mat map(height, width, CV_32FC(channels));
  const char* src = data.data() + pos;
  for (int r = 0; r < height; ++r) {
    // Rows are stored bottom-to-top.
    std::memcpy(map.ptr<char>(height - 1 - r), src + r * row_bytes, row_bytes);
  }
  if (!little_endian) {  // big-endian data: swap every float (host is little-endian)
    auto* bytes = reinterpret_cast<unsigned char*>(map.data);
    for (std::uint64_t i = 0; i < need; i += 4) {
      std::swap(bytes[i], bytes[i + 3]);
      std::swap(bytes[i + 1], bytes[i + 2]);
    }
  }
  if (channels == 3) cv::cvtColor(map, map, cv::COLOR_RGB2BGR);
  return map;
}

// ---------------------------------------------------------------------------
// EXR

void WriteExr(const fs::path& path, const cv::Mat& map) {
  if (map.empty()) throw InputError(path.string(), "refusing to write an empty map");
  if (map.channels() != 1)
    throw InputError(path.string(), "EXR depth maps hold one channel, got " + std::to_string(map.channels()));
  EnableOpenCvExr();
  const cv::Mat f = ToFloat32(map);
  bool ok = false;
  try {
    ok = cv::imwrite(path.string(), f, {cv::IMWRITE_EXR_TYPE, cv::IMWRITE_EXR_TYPE_FLOAT});
  } catch (const cv::Exception& e) {
    throw InputError(path.string(), std::string("cannot write EXR: ") + e.what());
  }
  if (!ok) throw InputError(path.string(), "cannot write EXR");
}

ExrHeader ReadExrHeader(const fs::path& path) {
  const std::string file = path.string();
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(file, "cannot open file");
  // The header (magic, version, attributes up to an empty name) is read from
  // at most the first 1 MiB; attribute sizes are checked against what is there.
  constexpr std::size_t kMaxHeaderBytes = 1 << 20;
  std::error_code ec;
  const auto file_size = fs::file_size(path, ec);
  std::string data(ec ? kMaxHeaderBytes : std::min<std::size_t>(file_size, kMaxHeaderBytes), '\0');
  in.read(data.data(), static_cast<std::streamsize>(data.size()));
  data.resize(static_cast<std::size_t>(in.gcount()));
  std::size_t pos = 0;
  auto u32 = [&](const char* what) {
    if (data.size() - pos < 4) throw InputError(file, what, "EXR header is truncated");
    std::uint32_t v = 0;
    for (int i = 3; i >= 0; --i) v = (v << 8) | static_cast<unsigned char>(data[pos + i]);
    pos += 4;
    return v;
  };
  auto i32 = [&](const char* what) { return static_cast<std::int32_t>(u32(what)); };
  auto cstring = [&](const char* what, std::size_t max_len) {
    const std::size_t end = data.find('\0', pos);
    if (end == std::string::npos) throw InputError(file, what, "EXR header is truncated");
    if (end - pos > max_len) throw InputError(file, what, "EXR attribute name longer than " + std::to_string(max_len));
    std::string s = data.substr(pos, end - pos);
    pos = end + 1;
    return s;
  };
  if (u32("magic") != 20000630u) throw InputError(file, "magic", "not an OpenEXR file");
  const std::uint32_t version = u32("version");
  if ((version & 0xff) != 2) throw InputError(file, "version", "OpenEXR version " + std::to_string(version & 0xff) + " not supported");
  if (version & 0x800) throw InputError(file, "version", "deep EXR files are not depth maps");
  if (version & 0x1000) throw InputError(file, "version", "multi-part EXR files are not supported");
  const std::size_t max_name = (version & 0x400) ? 255 : 31;
  ExrHeader h;
  h.tiled = (version & 0x200) != 0;
  bool have_window = false, have_channels = false;
  long long width = 0, height = 0;
  while (true) {
    const std::string name = cstring("attribute name", max_name);
    if (name.empty()) break;  // end of the header
    const std::string field = InputToken(name);  // the file's bytes, up to 255 of them
    const std::string type = cstring(field.c_str(), max_name);
    const std::uint32_t size = u32(field.c_str());
    if (size > data.size() - pos)
      throw InputError(file, field, "EXR attribute of " + std::to_string(size) + " bytes is truncated");
    const std::size_t value_end = pos + size;
    if (name == "dataWindow") {
      if (type != "box2i" || size != 16) throw InputError(file, field, "expected a box2i of 16 bytes");
      const long long x0 = i32("dataWindow"), y0 = i32("dataWindow"), x1 = i32("dataWindow"), y1 = i32("dataWindow");
      width = x1 - x0 + 1;
      height = y1 - y0 + 1;
      have_window = true;
    } else if (name == "channels") {
      if (type != "chlist") throw InputError(file, field, "expected a chlist");
      int n = 0;
      while (pos < value_end && data[pos] != '\0') {
        cstring("channels", max_name);
        if (value_end < pos || value_end - pos < 16) throw InputError(file, field, "channel list is truncated");
        const std::int32_t pixel_type = i32("channels");
        pos += 8;  // pLinear, reserved, xSampling
        pos += 4;  // ySampling
        if (pixel_type < 0 || pixel_type > 2)
          throw InputError(file, field, "unknown pixel type " + std::to_string(pixel_type));
        if (++n > kMaxExrChannels)
          throw InputError(file, field, "more than " + std::to_string(kMaxExrChannels) + " channels");
      }
      if (pos >= value_end) throw InputError(file, field, "channel list is not terminated");
      h.channels = n;
      have_channels = true;
    }
    pos = value_end;
  }
  if (!have_window) throw InputError(file, "dataWindow", "missing");
  if (!have_channels || h.channels == 0) throw InputError(file, "channels", "no channel");
  if (width < 1 || height < 1 || width > kMaxExrSide || height > kMaxExrSide || width * height > kMaxExrPixels)
    throw InputError(file, "dataWindow",
                     std::to_string(width) + "x" + std::to_string(height) + " is not a depth map size (at most " +
                         std::to_string(kMaxExrSide) + " on a side, " + std::to_string(kMaxExrPixels) + " pixels)");
  h.width = static_cast<int>(width);
  h.height = static_cast<int>(height);
  return h;
}

cv::Mat ReadExr(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) throw InputError(path.string(), "EXR file does not exist");
  ReadExrHeader(path);  // sizes checked before OpenCV allocates anything
  EnableOpenCvExr();
  cv::Mat raw;
  try {
    raw = cv::imread(path.string(), cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception& e) {
    throw InputError(path.string(), std::string("cannot decode EXR: ") + e.what());
  }
  if (raw.empty())
    throw InputError(path.string(), "cannot read EXR (corrupt file or OpenCV built without OpenEXR)");
  cv::Mat first;
  if (raw.channels() == 1)
    first = raw;
  else
    cv::extractChannel(raw, first, 0);
  return ToFloat32(first);
}

cv::Mat ReadDepthMap(const fs::path& path) {
  const std::string ext = LowerExtension(path);
  if (ext == ".pfm") return ReadPfm(path);
  if (ext == ".exr") return ReadExr(path);
  throw InputError(path.string(), "unsupported depth map format " + InputToken(ext) + " (expected .pfm or .exr)");
}

// ---------------------------------------------------------------------------
// Previews

cv::Mat ColorizeMap(const cv::Mat& map, double min_value, double max_value) {
  if (map.empty()) return cv::Mat();
  if (map.channels() != 1) throw std::invalid_argument("ColorizeMap needs a single-channel map");
  const cv::Mat f = ToFloat32(map);
  cv::Mat valid(f.size(), CV_8U);
  std::vector<float> values;
  for (int r = 0; r < f.rows; ++r) {
    const float* row = f.ptr<float>(r);
    auto* v = valid.ptr<std::uint8_t>(r);
    for (int c = 0; c < f.cols; ++c) {
      v[c] = std::isfinite(row[c]) && row[c] != 0.0f ? 255 : 0;
      if (v[c]) values.push_back(row[c]);
    }
  }
  // Auto range from the 2nd to 98th percentile: a few far outliers (a wall
  // behind the scene) would otherwise squash the object into one colour.
  double lo = 0, hi = 1;
  if (!values.empty()) {
    const size_t a = values.size() / 50, b = values.size() - 1 - values.size() / 50;
    std::nth_element(values.begin(), values.begin() + a, values.end());
    lo = values[a];
    std::nth_element(values.begin(), values.begin() + b, values.end());
    hi = values[b];
  }
  if (min_value < max_value) {
    lo = min_value;
    hi = max_value;
  }
  const double range = hi > lo ? hi - lo : 1.0;
  cv::Mat scaled(f.size(), CV_8U, cv::Scalar(0));
  for (int r = 0; r < f.rows; ++r) {
    const float* row = f.ptr<float>(r);
    const auto* v = valid.ptr<std::uint8_t>(r);
    auto* out = scaled.ptr<std::uint8_t>(r);
    for (int c = 0; c < f.cols; ++c)
      if (v[c])
        out[c] = static_cast<std::uint8_t>(std::clamp((row[c] - lo) / range * 255.0 + 0.5, 0.0, 255.0));
  }
  cv::Mat colored;
  cv::applyColorMap(scaled, colored, cv::COLORMAP_TURBO);
  colored.setTo(cv::Scalar::all(0), valid == 0);
  return colored;
}

void WriteDepthPreview(const fs::path& path, const cv::Mat& map, const cv::Mat& frame, double min_value,
                       double max_value) {
  if (map.empty()) throw InputError(path.string(), "refusing to write a preview of an empty map");
  cv::Mat image = ColorizeMap(map, min_value, max_value);
  if (!frame.empty()) {
    cv::Mat left;
    if (frame.depth() == CV_8U)
      left = frame;
    else
      frame.convertTo(left, CV_8U, 255.0);
    if (left.channels() == 1)
      cv::cvtColor(left, left, cv::COLOR_GRAY2BGR);
    else if (left.channels() == 4)
      cv::cvtColor(left, left, cv::COLOR_BGRA2BGR);
    if (left.rows != image.rows) {
      const int width =
          std::max(1, static_cast<int>(std::lround(left.cols * double(image.rows) / left.rows)));
      cv::resize(left, left, cv::Size(width, image.rows), 0, 0, cv::INTER_AREA);
    }
    cv::hconcat(left, image, image);
  }
  bool ok = false;
  try {
    ok = cv::imwrite(path.string(), image);
  } catch (const cv::Exception& e) {
    throw InputError(path.string(), std::string("cannot write preview: ") + e.what());
  }
  if (!ok) throw InputError(path.string(), "cannot write preview");
}

}  // namespace lfrecon
