#pragma once
// Frames to a video file with OpenCV's VideoWriter, for the tests and the
// benchmark of `lfrecon poses`: FFV1 (lossless) in Matroska when Debian's
// OpenCV/FFmpeg has it, else Motion-JPEG at quality 100 in AVI.
#include <filesystem>
#include <functional>
#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>
#include <stdexcept>
#include <string>

namespace lfrecon::testing {

// Writes frame(0) .. frame(n - 1) (8-bit BGR, all one size) to `stem` + ".mkv"
// (FFV1) or ".avi" (MJPG); returns the file written and its codec in *codec.
inline std::filesystem::path WriteVideo(const std::filesystem::path& stem, int n, double fps,
                                        const std::function<cv::Mat(int)>& frame, std::string* codec = nullptr) {
  const cv::Mat first = frame(0);
  struct Choice {
    const char* ext;
    int fourcc;
    const char* name;
  };
  const Choice choices[] = {{".mkv", cv::VideoWriter::fourcc('F', 'F', 'V', '1'), "FFV1"},
                            {".avi", cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), "MJPG"}};
  for (const Choice& c : choices) {
    std::filesystem::path path = stem;
    path += c.ext;
    cv::VideoWriter writer;
    if (!writer.open(path.string(), cv::CAP_FFMPEG, c.fourcc, fps, first.size(), true)) continue;
    if (c.fourcc == cv::VideoWriter::fourcc('M', 'J', 'P', 'G')) writer.set(cv::VIDEOWRITER_PROP_QUALITY, 100);
    writer.write(first);
    for (int i = 1; i < n; ++i) writer.write(frame(i));
    writer.release();
    if (codec) *codec = c.name;
    return path;
  }
  throw std::runtime_error("no VideoWriter codec (FFV1, MJPG) available for " + stem.string());
}

}  // namespace lfrecon::testing
