#include "fusion/surface_evidence.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace lfrecon {

CompactDepthView::CompactDepthView(const PinholeView& view, const DepthMap& depth, const BoundingBox& volume)
    : view_(view) {
  const int rows = view.height, cols = view.width;
  grid_width_ = cols;
  grid_height_ = rows;
  pixels_.assign(static_cast<std::size_t>(rows) * cols, Pixel{});
  if (depth.depth.empty()) return;
  CV_Assert(depth.depth.type() == CV_32F && depth.depth.rows == rows && depth.depth.cols == cols);
  const bool has_conf = !depth.confidence.empty();
  const bool has_label = !depth.label.empty();
  if (has_conf) CV_Assert(depth.confidence.type() == CV_32F && depth.confidence.size() == depth.depth.size());
  if (has_label) CV_Assert(depth.label.type() == CV_8U && depth.label.size() == depth.depth.size());

  // Planar depth range of V in this view.
  near_ = std::numeric_limits<double>::infinity();
  far_ = -near_;
  for (int k = 0; k < 8; ++k) {
    const Eigen::Vector3d corner((k & 1) ? volume.max.x() : volume.min.x(), (k & 2) ? volume.max.y() : volume.min.y(),
                                 (k & 4) ? volume.max.z() : volume.min.z());
    const double z = (view.R * corner + view.t).z();
    near_ = std::min(near_, z);
    far_ = std::max(far_, z);
  }
  if (far_ <= 0) {  // V is behind the camera: this view says nothing
    near_ = far_ = 0;
    return;
  }
  near_ = std::max(near_, 1e-6);
  step_ = (far_ - near_) / 65533.0;
  if (step_ <= 0) step_ = 1e-9;

  for (int r = 0; r < rows; ++r) {
    const float* d = depth.depth.ptr<float>(r);
    const float* c = has_conf ? depth.confidence.ptr<float>(r) : nullptr;
    const std::uint8_t* l = has_label ? depth.label.ptr<std::uint8_t>(r) : nullptr;
    for (int col = 0; col < cols; ++col) {
      const float z = d[col];
      const float conf = c ? c[col] : 1.0f;
      if (!(conf > 0) || !std::isfinite(z) || z < 0) continue;
      DepthLabel label;
      if (l) {
        label = static_cast<DepthLabel>(l[col]);
      } else {
        if (!(z > 0)) continue;
        const Eigen::Vector3d x = view.Unproject(Eigen::Vector2d(col + 0.5, r + 0.5), z);
        label = volume.Contains(x) ? DepthLabel::kForeground : DepthLabel::kBackground;
      }
      Pixel& p = pixels_[static_cast<std::size_t>(r) * cols + col];
      if (label == DepthLabel::kForeground) {
        if (!(z > 0)) continue;
        const double q = std::clamp((z - near_) / step_, 0.0, 65532.0);
        p.depth = static_cast<std::uint16_t>(1 + std::lround(q));
      } else if (label == DepthLabel::kBackground) {
        if (z == 0 || z >= far_) {
          p.depth = kBeyond;
        } else if (z <= near_) {
          continue;  // a background surface in front of all of V occludes it
        } else {
          const double q = std::clamp((z - near_) / step_, 0.0, 65532.0);
          p.depth = static_cast<std::uint16_t>(1 + std::lround(q));
        }
      } else {
        continue;
      }
      p.label = static_cast<std::uint8_t>(label);
      p.confidence = static_cast<std::uint8_t>(std::lround(std::clamp(conf, 0.0f, 1.0f) * 255.0f));
      if (p.confidence == 0) p = Pixel{};
    }
  }
}

double CompactDepthView::Depth(const Pixel& p) const {
  if (p.depth == 0) return 0;
  if (p.depth == kBeyond) return std::numeric_limits<double>::infinity();
  return near_ + (p.depth - 1) * step_;
}

int CompactDepthView::CountForeground() const {
  int n = 0;
  for (const Pixel& p : pixels_) n += (p.depth != 0 && p.label == static_cast<std::uint8_t>(DepthLabel::kForeground));
  return n;
}

CompactDepthView CompactDepthView::Coarsened(double band) const {
  CompactDepthView out;
  out.view_ = view_;
  out.near_ = near_;
  out.far_ = far_;
  out.step_ = step_;
  out.block_ = 2 * block_;
  out.grid_width_ = (grid_width_ + 1) / 2;
  out.grid_height_ = (grid_height_ + 1) / 2;
  out.pixels_.assign(static_cast<std::size_t>(out.grid_width_) * out.grid_height_, Pixel{});
  if (pixels_.empty()) return out;
  const double band_codes = step_ > 0 ? band / step_ : 0;
  const auto fg = static_cast<std::uint8_t>(DepthLabel::kForeground);
  const auto bg = static_cast<std::uint8_t>(DepthLabel::kBackground);
  for (int r = 0; r < out.grid_height_; ++r) {
    for (int c = 0; c < out.grid_width_; ++c) {
      const Pixel* kids[4];
      int n = 0;
      for (int k = 0; k < 4; ++k) {
        const int rr = 2 * r + (k >> 1), cc = 2 * c + (k & 1);
        if (rr >= grid_height_ || cc >= grid_width_) continue;
        const Pixel& p = at(rr, cc);
        if (p.depth != 0) kids[n++] = &p;
      }
      Pixel& q = out.pixels_[static_cast<std::size_t>(r) * out.grid_width_ + c];
      std::uint16_t front = kBeyond;
      bool any_fg = false;
      for (int k = 0; k < n; ++k)
        if (kids[k]->label == fg) {
          any_fg = true;
          front = std::min(front, kids[k]->depth);
        }
      if (any_fg) {
        int sum = 0, m = 0;
        for (int k = 0; k < n; ++k)
          if (kids[k]->label == fg && kids[k]->depth - front <= band_codes) {
            sum += kids[k]->confidence;
            ++m;
          }
        q.depth = front;
        q.label = fg;
        q.confidence = static_cast<std::uint8_t>((sum + m / 2) / m);
        continue;
      }
      int sum = 0, m = 0;
      for (int k = 0; k < n; ++k)
        if (kids[k]->label == bg) {
          front = std::min(front, kids[k]->depth);  // kBeyond is the largest code
          sum += kids[k]->confidence;
          ++m;
        }
      if (m == 0) continue;
      q.depth = front;
      q.label = bg;
      q.confidence = static_cast<std::uint8_t>((sum + m / 2) / m);
      if (q.confidence == 0) q = Pixel{};
    }
  }
  return out;
}

SurfaceEvidence::SurfaceEvidence(const CompactDepthView& view, const FusionOptions& options) : view_(&view) {
  P_ = view.view().K * view.view().R;
  p_ = view.view().K * view.view().t;
  sigma_v_ = options.SigmaV();
  band_ = options.BandHalfWidth();
  carve_front_ = options.free_space_margin >= 0;
  margin_ = options.free_space_margin * sigma_v_;
  two_over_s2_ = 2.0 / (options.sigma_s * options.sigma_s);
  log_clamp_lo_ = std::log(options.probability_clamp);
  log_clamp_hi_ = std::log1p(-options.probability_clamp);
  bilinear_ = options.sampling == DepthSampling::kBilinear;
}

double SurfaceEvidence::Probability(double c, double sigma_s, double clamp) {
  const double p = 1.0 / (1.0 + std::exp(-2.0 * c / (sigma_s * sigma_s)));
  return std::clamp(p, clamp, 1.0 - clamp);
}

bool SurfaceEvidence::Sample(double u, double v, DepthLabel* label, double* depth, double* confidence) const {
  const CompactDepthView& m = *view_;
  if (m.block() > 1) {  // stored pixels are blocks: sample in block units
    u /= m.block();
    v /= m.block();
  }
  const int col = static_cast<int>(u), row = static_cast<int>(v);
  const CompactDepthView::Pixel& p = m.at(row, col);
  if (p.depth == 0) return false;
  *label = CompactDepthView::Label(p);
  *depth = m.Depth(p);
  *confidence = CompactDepthView::Confidence(p);
  if (!bilinear_) return true;

  // Bilinear over the neighbours that agree with the nearest pixel.
  const double x = u - 0.5, y = v - 0.5;
  const int c0 = static_cast<int>(std::floor(x)), r0 = static_cast<int>(std::floor(y));
  const double fx = x - c0, fy = y - r0;
  const bool beyond = p.depth == CompactDepthView::kBeyond;
  double wsum = 0, dsum = 0, csum = 0;
  for (int k = 0; k < 4; ++k) {
    const int rr = r0 + (k >> 1), cc = c0 + (k & 1);
    if (rr < 0 || cc < 0 || rr >= m.grid_height() || cc >= m.grid_width()) continue;
    const CompactDepthView::Pixel& q = m.at(rr, cc);
    if (q.depth == 0 || q.label != p.label) continue;
    if (beyond != (q.depth == CompactDepthView::kBeyond)) continue;
    const double dq = m.Depth(q);
    if (!beyond && std::abs(dq - *depth) > band_) continue;
    const double w = ((k & 1) ? fx : 1 - fx) * ((k >> 1) ? fy : 1 - fy);
    wsum += w;
    if (!beyond) dsum += w * dq;
    csum += w * CompactDepthView::Confidence(q);
  }
  if (wsum > 1e-12) {
    if (!beyond) *depth = dsum / wsum;
    *confidence = csum / wsum;
  }
  return true;
}

bool SurfaceEvidence::LogProbability(const Eigen::Vector3d& x, float* log_p, double* c_out) const {
  const Eigen::Vector3d h = P_ * x + p_;
  const double z = h.z();
  if (!(z > 1e-9)) return false;
  const double u = h.x() / z, v = h.y() / z;
  if (!(u >= 0 && v >= 0 && u < view_->width() && v < view_->height())) return false;
  DepthLabel label;
  double d, conf;
  if (!Sample(u, v, &label, &d, &conf)) return false;
  if (!(conf > 0)) return false;
  double c;
  if (label == DepthLabel::kForeground) {
    const double delta = z - d;  // > 0: behind the observed surface
    if (delta > band_) return false;  // occluded: this view says nothing
    if (carve_front_ && delta < -margin_) {
      c = -conf;  // on the free part of the ray in front of the surface
    } else {
      c = conf * std::exp(-delta * delta / (2.0 * sigma_v_ * sigma_v_));  // eq. 11
    }
  } else {
    if (z > d) return false;  // behind a background surface that lies in front of it
    c = -conf;                // free space along a background ray (§1.5)
  }
  // Eqs. 12-13: log(1 / (1 + exp(-2c/σ_s^2))), computed stably, then clamped.
  const double a = -two_over_s2_ * c;
  const double lp = a > 0 ? -(a + std::log1p(std::exp(-a))) : -std::log1p(std::exp(a));
  *log_p = static_cast<float>(std::clamp(lp, log_clamp_lo_, log_clamp_hi_));
  if (c_out) *c_out = c;
  return true;
}

}  // namespace lfrecon
