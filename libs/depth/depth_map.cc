#include "depth/depth_map.h"

#include <cmath>
#include <stdexcept>

namespace lfrecon {

PackedDepthMap PackedDepthMap::Pack(const DepthMap& map) {
  PackedDepthMap p;
  if (map.depth.empty()) return p;
  if (map.depth.type() != CV_32F) throw std::invalid_argument("PackedDepthMap: depth must be CV_32F");
  p.rows_ = map.depth.rows;
  p.cols_ = map.depth.cols;
  p.has_confidence_ = !map.confidence.empty();
  p.has_label_ = !map.label.empty();
  if ((p.has_confidence_ && (map.confidence.size() != map.depth.size() || map.confidence.type() != CV_32F)) ||
      (p.has_label_ && (map.label.size() != map.depth.size() || map.label.type() != CV_8U)))
    throw std::invalid_argument("PackedDepthMap: confidence/label must match the depth map");
  for (int r = 0; r < p.rows_; ++r) {
    const float* d = map.depth.ptr<float>(r);
    const float* c = p.has_confidence_ ? map.confidence.ptr<float>(r) : nullptr;
    const std::uint8_t* l = p.has_label_ ? map.label.ptr<std::uint8_t>(r) : nullptr;
    for (int k = 0; k < p.cols_; ++k) {
      // Anything but +0 is kept (NaN != 0; -0.0 by its sign bit).
      const bool set = d[k] != 0.0f || std::signbit(d[k]) || (c && (c[k] != 0.0f || std::signbit(c[k]))) ||
                       (l && l[k] != 0);
      if (!set) continue;
      p.index_.push_back(static_cast<std::uint32_t>(r * p.cols_ + k));
      p.depth_.push_back(d[k]);
      if (c) p.confidence_.push_back(c[k]);
      if (l) p.label_.push_back(l[k]);
    }
  }
  p.index_.shrink_to_fit();
  p.depth_.shrink_to_fit();
  p.confidence_.shrink_to_fit();
  p.label_.shrink_to_fit();
  return p;
}

DepthMap PackedDepthMap::Unpack() const {
  DepthMap m;
  if (rows_ == 0) return m;
  m.depth = cv::Mat::zeros(rows_, cols_, CV_32F);
  if (has_confidence_) m.confidence = cv::Mat::zeros(rows_, cols_, CV_32F);
  if (has_label_) m.label = cv::Mat::zeros(rows_, cols_, CV_8U);
  float* d = m.depth.ptr<float>();
  float* c = has_confidence_ ? m.confidence.ptr<float>() : nullptr;
  std::uint8_t* l = has_label_ ? m.label.ptr<std::uint8_t>() : nullptr;
  for (std::size_t i = 0; i < index_.size(); ++i) {
    d[index_[i]] = depth_[i];
    if (c) c[index_[i]] = confidence_[i];
    if (l) l[index_[i]] = label_[i];
  }
  return m;
}

std::size_t PackedDepthMap::Bytes() const {
  return index_.capacity() * sizeof(std::uint32_t) + (depth_.capacity() + confidence_.capacity()) * sizeof(float) +
         label_.capacity();
}

}  // namespace lfrecon
