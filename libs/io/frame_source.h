#pragma once
// Streams of frames. Frames are read lazily, one at a time: no source holds
// the whole sequence in memory. Images are CV_32FC3, BGR (OpenCV's channel
// order), values in [0, 1].
#include <filesystem>
#include <cstdint>
#include <memory>
#include <optional>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace lfrecon {

struct Frame {
  int index = -1;    // position in the sequence
  std::string name;  // image name (file name relative to the image folder), or "frame_NNNNN" for video
  cv::Mat image;     // CV_32FC3 BGR in [0, 1]
};

class FrameSource {
 public:
  virtual ~FrameSource() = default;
  // Number of frames; for video this is the container's count, which may be an estimate.
  virtual int NumFrames() const = 0;
  // Next frame in order; false at the end. Throws InputError for an unreadable frame.
  virtual bool Next(Frame* frame) = 0;
  // Random access. Throws InputError for an unreadable frame or bad index.
  virtual Frame Read(int index) = 0;
};

// Name order for frame sequences: digit runs compare by value ("f2.png" < "f10.png"),
// everything else byte-wise; equals plain order for zero-padded names.
bool NaturalNameLess(const std::string& a, const std::string& b);

// Converts an 8- or 16-bit, 1/3/4-channel image to CV_32FC3 BGR in [0, 1].
cv::Mat ToFloatBgr(const cv::Mat& image);
// A frame as windows hold it: CV_8UC3 when the CV_32FC3 frame is exactly
// ToFloatBgr of an 8-bit image (as decoded PNG/JPEG/video frames are; a
// quarter of the memory), else the frame itself. ExpandFrame gives back the
// same floats bit for bit.
cv::Mat CompactFrame(const cv::Mat& frame);
cv::Mat ExpandFrame(const cv::Mat& pixels);
// What a PNG or JPEG header says, read without decoding any pixel.
struct ImageHeader {
  std::string format;  // "png" or "jpeg"
  int width = 0, height = 0;  // 0: no size found (JPEG without a frame header)
  // JPEG: the marker structure reaches the end-of-image marker (EOI). A file
  // cut short lacks it; libjpeg then only warns and fills the rest with grey.
  bool complete = true;
};
// The header of PNG (IHDR) or JPEG (SOFn; EOI searched by walking the
// segments and entropy-coded data) bytes; nullopt for other formats.
std::optional<ImageHeader> ReadImageHeader(const std::string& bytes);

// Frames larger than this are refused before they are decoded (~1.2 GB as floats).
constexpr std::int64_t kMaxImagePixels = std::int64_t{100} << 20;

// Decodes PNG or JPEG bytes (ReadImageHeader recognises them) as ReadImageFloat
// does a file of them: the header checked before any pixel is decoded (the size
// against `expect` when given, and kMaxImagePixels; a truncated JPEG refused),
// IMREAD_UNCHANGED without EXIF rotation, then ToFloatBgr. Throws InputError
// naming `what` (also for bytes of another format).
cv::Mat DecodeImageFloat(const std::string& bytes, const std::string& what, std::optional<cv::Size> expect = std::nullopt);
// Reads one image file as CV_32FC3 BGR in [0, 1]; throws InputError naming it.
// PNG and JPEG headers are checked before decoding: the size against `expect`
// (the frame's camera, when given) and kMaxImagePixels; a JPEG without its
// end-of-image marker (truncated) is refused rather than decoded half grey.
// Every other format's size is read from its header too (image_header.h: TIFF,
// BMP, WebP, EXR, PNM, ...) and checked the same way before decoding; a format
// whose header cannot be read is refused, naming the file.
cv::Mat ReadImageFloat(const std::filesystem::path& path, std::optional<cv::Size> expect = std::nullopt);
// Writes CV_32FC3 [0, 1] (or 8-bit) to PNG/JPEG (by extension); throws InputError naming it.
void WriteImageFloat(const std::filesystem::path& path, const cv::Mat& image, int jpeg_quality = 95);

// A list of image files, in the given order.
class ImageFolderSource : public FrameSource {
 public:
  // `names` are relative to `folder`.
  ImageFolderSource(std::filesystem::path folder, std::vector<std::string> names);
  // All images in `folder` (png, jpg, jpeg, tif, tiff, exr, bmp), sorted by NaturalNameLess.
  static std::unique_ptr<ImageFolderSource> FromFolder(const std::filesystem::path& folder);

  int NumFrames() const override { return static_cast<int>(names_.size()); }
  bool Next(Frame* frame) override;
  Frame Read(int index) override;
  const std::vector<std::string>& names() const { return names_; }
  // Frame k must be sizes[k] (its camera's size): checked from the header, before decoding.
  void ExpectSizes(std::vector<cv::Size> sizes) { sizes_ = std::move(sizes); }

 private:
  std::filesystem::path folder_;
  std::vector<std::string> names_;
  std::vector<cv::Size> sizes_;
  int next_ = 0;
};

// A video file read through OpenCV's VideoCapture.
class VideoSource : public FrameSource {
 public:
  explicit VideoSource(const std::filesystem::path& path);
  ~VideoSource() override;
  int NumFrames() const override;
  bool Next(Frame* frame) override;
  Frame Read(int index) override;  // seeks; sequential Next() is much faster

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace lfrecon
