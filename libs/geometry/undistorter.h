#pragma once
// Removes lens distortion from whole frames (OpenCV remap with precomputed
// maps). The output camera is PINHOLE with the input's focal lengths and
// principal point, so pixels near the centre keep their scale.
#include <opencv2/core.hpp>

#include "geometry/camera.h"

namespace lfrecon {

class Undistorter {
 public:
  explicit Undistorter(const Camera& distorted);

  const Camera& undistorted_camera() const { return undistorted_; }
  bool is_identity() const { return identity_; }
  // Any image type cv::remap accepts; size must equal the camera's.
  cv::Mat Apply(const cv::Mat& image) const;

 private:
  Camera distorted_;
  Camera undistorted_;
  bool identity_ = false;
  cv::Mat map_x_, map_y_;
};

}  // namespace lfrecon
