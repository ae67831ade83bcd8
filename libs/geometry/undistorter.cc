#include "geometry/undistorter.h"

#include <opencv2/imgproc.hpp>
#include <stdexcept>

namespace lfrecon {

Undistorter::Undistorter(const Camera& distorted) : distorted_(distorted) {
  undistorted_ = Camera::Pinhole(distorted.width, distorted.height, distorted.fx(), distorted.fy(), distorted.cx(),
                                 distorted.cy());
  identity_ = !distorted.HasDistortion();
  if (identity_) return;
  map_x_.create(distorted.height, distorted.width, CV_32F);
  map_y_.create(distorted.height, distorted.width, CV_32F);
  for (int r = 0; r < distorted.height; ++r) {
    for (int c = 0; c < distorted.width; ++c) {
      // Output pixel (c, r) has COLMAP centre (c + 0.5, r + 0.5); OpenCV's
      // remap indexes source pixels by their centres, hence the -0.5.
      const Eigen::Vector2d n = undistorted_.ImageToNormalized(Eigen::Vector2d(c + 0.5, r + 0.5));
      const Eigen::Vector2d src = distorted.NormalizedToImage(n);
      map_x_.at<float>(r, c) = static_cast<float>(src.x() - 0.5);
      map_y_.at<float>(r, c) = static_cast<float>(src.y() - 0.5);
    }
  }
}

cv::Mat Undistorter::Apply(const cv::Mat& image) const {
  if (image.cols != distorted_.width || image.rows != distorted_.height)
    throw std::invalid_argument("image size " + std::to_string(image.cols) + "x" + std::to_string(image.rows) +
                                " does not match the camera's " + std::to_string(distorted_.width) + "x" +
                                std::to_string(distorted_.height));
  if (identity_) return image;
  cv::Mat out;
  cv::remap(image, out, map_x_, map_y_, cv::INTER_LINEAR, cv::BORDER_REPLICATE);
  return out;
}

}  // namespace lfrecon
