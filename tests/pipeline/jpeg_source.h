#pragma once
// A FrameSource whose frames go through a JPEG round trip (the degraded
// captures of the pipeline tests).
#include <memory>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <vector>

#include "io/frame_source.h"

namespace lfrecon {

class JpegSource : public FrameSource {
 public:
  JpegSource(std::unique_ptr<FrameSource> source, int quality) : source_(std::move(source)), quality_(quality) {}
  int NumFrames() const override { return source_->NumFrames(); }
  bool Next(Frame* frame) override {
    if (!source_->Next(frame)) return false;
    Encode(frame);
    return true;
  }
  Frame Read(int index) override {
    Frame f = source_->Read(index);
    Encode(&f);
    return f;
  }

 private:
  void Encode(Frame* f) const {
    cv::Mat u8;
    f->image.convertTo(u8, CV_8UC3, 255.0);
    std::vector<uchar> bytes;
    cv::imencode(".jpg", u8, bytes, {cv::IMWRITE_JPEG_QUALITY, quality_});
    cv::imdecode(bytes, cv::IMREAD_COLOR).convertTo(f->image, CV_32FC3, 1.0 / 255.0);
  }
  std::unique_ptr<FrameSource> source_;
  int quality_;
};

}  // namespace lfrecon
