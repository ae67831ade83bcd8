#pragma once
// Streams of frames. Frames are read lazily, one at a time: no source holds
// the whole sequence in memory. Images are CV_32FC3, BGR (OpenCV's channel
// order), values in [0, 1].
#include <filesystem>
#include <memory>
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
// Reads one image file as CV_32FC3 BGR in [0, 1]; throws InputError naming it.
cv::Mat ReadImageFloat(const std::filesystem::path& path);
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

 private:
  std::filesystem::path folder_;
  std::vector<std::string> names_;
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
