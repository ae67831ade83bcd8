#include "propagation/edge_preview.h"

#include <opencv2/imgproc.hpp>

#include "io/frame_source.h"
#include "propagation/bidirectional_photoconsistency.h"
#include "util/error.h"

namespace lfrecon {

cv::Mat RenderEdgePreview(const cv::Mat& frame, const cv::Mat& edge_classes, bool legend) {
  cv::Mat bgr8;
  if (frame.depth() == CV_8U) bgr8 = frame;
  else frame.convertTo(bgr8, CV_8U, 255.0);
  if (bgr8.channels() == 1) cv::cvtColor(bgr8, bgr8, cv::COLOR_GRAY2BGR);
  cv::Mat grey;
  cv::cvtColor(bgr8, grey, cv::COLOR_BGR2GRAY);
  cv::Mat out;
  // Dimmed grey so the two edge colours stand out.
  grey.convertTo(grey, CV_8U, 0.55, 20);
  cv::cvtColor(grey, out, cv::COLOR_GRAY2BGR);
  if (edge_classes.size() == out.size() && edge_classes.type() == CV_8U) {
    const cv::Vec3b sil(static_cast<uchar>(kSilhouetteColor[0]), static_cast<uchar>(kSilhouetteColor[1]),
                        static_cast<uchar>(kSilhouetteColor[2]));
    const cv::Vec3b tex(static_cast<uchar>(kTextureColor[0]), static_cast<uchar>(kTextureColor[1]),
                        static_cast<uchar>(kTextureColor[2]));
    for (int r = 0; r < out.rows; ++r) {
      const std::uint8_t* k = edge_classes.ptr<std::uint8_t>(r);
      cv::Vec3b* o = out.ptr<cv::Vec3b>(r);
      for (int c = 0; c < out.cols; ++c) {
        if (k[c] == static_cast<std::uint8_t>(EdgeClass::kSilhouette)) o[c] = sil;
        else if (k[c] == static_cast<std::uint8_t>(EdgeClass::kTexture)) o[c] = tex;
      }
    }
  }
  if (legend && out.cols >= 160 && out.rows >= 40) {
    const double scale = std::max(0.4, out.cols / 1600.0);
    const int thick = std::max(1, static_cast<int>(std::lround(scale * 2)));
    const int line = static_cast<int>(std::lround(24 * scale / 0.6));
    cv::rectangle(out, cv::Rect(0, 0, static_cast<int>(170 * scale / 0.4), 2 * line + 8), cv::Scalar(0, 0, 0),
                  cv::FILLED);
    cv::putText(out, "silhouette", cv::Point(6, line), cv::FONT_HERSHEY_SIMPLEX, scale, kSilhouetteColor, thick,
                cv::LINE_AA);
    cv::putText(out, "texture", cv::Point(6, 2 * line), cv::FONT_HERSHEY_SIMPLEX, scale, kTextureColor, thick,
                cv::LINE_AA);
  }
  return out;
}

void WriteEdgePreview(const std::filesystem::path& path, const cv::Mat& frame, const cv::Mat& edge_classes) {
  WriteImageFloat(path, RenderEdgePreview(frame, edge_classes));
}

}  // namespace lfrecon
