#pragma once
// Per-view depth and confidence maps: CV_32F, planar depth in metres (0 where
// there is none), confidence in [0, 1]. PFM (Portable Float Map, the format
// COLMAP and most MVS tools read) and OpenEXR (single channel, float32), and
// colour-mapped PNG previews for people.
#include <filesystem>
#include <opencv2/core.hpp>

namespace lfrecon {

// PFM stores rows bottom-to-top; these functions flip so row 0 is the top.
void WritePfm(const std::filesystem::path& path, const cv::Mat& map);
cv::Mat ReadPfm(const std::filesystem::path& path);

// OpenCV decodes EXR only when OPENCV_IO_ENABLE_OPENEXR=1 is in the environment
// before its first EXR use (it caches the setting). Sets it once; call before any
// cv::imread/imwrite of an EXR outside this library (ReadExr/WriteExr call it).
void EnableOpenCvExr();

// Single-channel float32 EXR. Reading a multi-channel EXR keeps its first channel.
// ReadExr checks the header (ReadExrHeader) before OpenCV decodes anything.
void WriteExr(const std::filesystem::path& path, const cv::Mat& map);
cv::Mat ReadExr(const std::filesystem::path& path);

// What an OpenEXR header says, read without decoding: a single-part image
// (scanline or tiled) whose data window is at most kMaxExrSide on a side and
// kMaxExrPixels in all, with 1..kMaxExrChannels channels. Throws InputError
// naming the file and the attribute otherwise (deep and multi-part files too).
constexpr long long kMaxExrSide = 1 << 15;
constexpr long long kMaxExrPixels = 1ll << 26;  // 256 MiB as one float channel
constexpr int kMaxExrChannels = 64;
struct ExrHeader {
  int width = 0, height = 0;
  int channels = 0;
  bool tiled = false;
};
ExrHeader ReadExrHeader(const std::filesystem::path& path);

// Reads .pfm or .exr by extension.
cv::Mat ReadDepthMap(const std::filesystem::path& path);

// Colour-maps `map` (turbo) between `min_value` and `max_value` (auto: 2nd-98th percentile of the
// valid values when min >= max); invalid (0 or non-finite) pixels are black.
// If `frame` is given (CV_32FC3 in [0,1] or 8-bit), it is placed on the left
// and the map on the right.
cv::Mat ColorizeMap(const cv::Mat& map, double min_value = 0, double max_value = 0);
void WriteDepthPreview(const std::filesystem::path& path, const cv::Mat& map, const cv::Mat& frame = cv::Mat(),
                       double min_value = 0, double max_value = 0);

}  // namespace lfrecon
