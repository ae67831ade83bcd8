#include "geometry/undistorter.h"

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

namespace lfrecon {

Undistorter::Undistorter(const Camera& distorted) : distorted_(distorted) {
  undistorted_ = Camera::Pinhole(distorted.width, distorted.height, distorted.fx(), distorted.fy(), distorted.cx(),
                                 distorted.cy());
  identity_ = !distorted.HasDistortion();
  if (identity_) return;
  // COLMAP's equidistant fisheye models are OpenCV's fisheye model (Kannala-Brandt,
  // theta_d = theta (1 + k1 theta^2 + ... + k4 theta^8)): its maps come from
  // cv::fisheye. OpenCV puts the upper-left pixel's centre at (0, 0), COLMAP at
  // (0.5, 0.5): both camera matrices take the principal point less 0.5.
  cv::Vec4d k(0, 0, 0, 0);
  bool fisheye = true;
  const std::vector<double>& p = distorted.params;
  switch (distorted.model) {
    case CameraModelId::kOpenCVFisheye: k = cv::Vec4d(p[4], p[5], p[6], p[7]); break;
    case CameraModelId::kSimpleRadialFisheye: k = cv::Vec4d(p[3], 0, 0, 0); break;
    case CameraModelId::kRadialFisheye: k = cv::Vec4d(p[3], p[4], 0, 0); break;
    default: fisheye = false;
  }
  if (fisheye) {
    const cv::Matx33d K(distorted.fx(), 0, distorted.cx() - 0.5, 0, distorted.fy(), distorted.cy() - 0.5, 0, 0, 1);
    cv::fisheye::initUndistortRectifyMap(K, k, cv::Matx33d::eye(), K, cv::Size(distorted.width, distorted.height),
                                         CV_32FC1, map_x_, map_y_);
    return;
  }
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
