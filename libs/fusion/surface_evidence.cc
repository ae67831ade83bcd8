#include "fusion/surface_evidence.h"

#include <algorithm>
#include <cmath>
#include <limits>

namespace lfrecon {
namespace {

// Set bits of w (SWAR: the build targets baseline x86-64, without POPCNT).
int PopCount(std::uint64_t w) {
  w = w - ((w >> 1) & 0x5555555555555555ULL);
  w = (w & 0x3333333333333333ULL) + ((w >> 2) & 0x3333333333333333ULL);
  w = (w + (w >> 4)) & 0x0f0f0f0f0f0f0f0fULL;
  return static_cast<int>((w * 0x0101010101010101ULL) >> 56);
}

}  // namespace

CompactDepthView::CompactDepthView(const PinholeView& view, const DepthMap& depth, const BoundingBox& volume)
    : view_(view) {
  const int rows = view.height, cols = view.width;
  grid_width_ = cols;
  grid_height_ = rows;
  pixels_.assign(static_cast<std::size_t>(rows) * cols, Pixel{});
  if (depth.depth.empty()) {
    ComputeTiles();
    return;
  }
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
    ComputeTiles();
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
  ComputeTiles();
}

void CompactDepthView::ComputeTiles() {
  tiles_wide_ = (grid_width_ + kTile - 1) / kTile;
  const int tiles_high = (grid_height_ + kTile - 1) / kTile;
  tile_max_.assign(static_cast<std::size_t>(tiles_wide_) * tiles_high, 0);
  if (pixels_.empty()) return;
  for (int r = 0; r < grid_height_; ++r)
    for (int c = 0; c < grid_width_; ++c) {
      std::uint16_t& t = tile_max_[static_cast<std::size_t>(r / kTile) * tiles_wide_ + c / kTile];
      t = std::max(t, at(r, c).depth);
    }
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
  if (pixels_.empty()) {
    out.ComputeTiles();
    return out;
  }
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
  out.ComputeTiles();
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

  // Tables for the nearest-sampling path of FromProjection. A stored
  // confidence is a byte b, c_i = b / 255, so free space (c = -c_i) takes 256
  // values. In the band, log P >= log(1-ε) (clamped) once c >= c_hi with
  // exp(-2 c_hi / σ_s^2) = ε / (1 - ε); eq. 11 gives c >= c_hi * (1 + 1e-9)
  // while |δ|^2 <= 2 σ_v^2 ln(c_i / (c_hi (1 + 1e-9))) (1 - 1e-9): the margins
  // are ~10^6 times double rounding, so the shortcut returns exactly what
  // the full formula returns (checked once more on c below).
  const double eps = options.probability_clamp;
  const double c_hi = -std::log(eps / (1.0 - eps)) / two_over_s2_ * (1.0 + 1e-9);
  const bool shortcut = LogPOfC(c_hi) == static_cast<float>(log_clamp_hi_);
  for (int b = 0; b < 256; ++b) {
    const double conf = b / 255.0;
    free_log_p_[b] = LogPOfC(-conf);
    clamped_within_sq_[b] = shortcut && conf > c_hi ? 2.0 * sigma_v_ * sigma_v_ * std::log(conf / c_hi) * (1.0 - 1e-9) : -1.0;
  }
}

SurfaceEvidence::SurfaceEvidence(const CompactDepthView& view, const SurfaceEvidence& other) : SurfaceEvidence(other) {
  view_ = &view;
  P_ = view.view().K * view.view().R;  // as in the constructor from options
  p_ = view.view().K * view.view().t;
}

float SurfaceEvidence::LogPOfC(double c) const {
  // Eqs. 12-13: log(1 / (1 + exp(-2c/σ_s^2))), computed stably, then clamped.
  const double a = -two_over_s2_ * c;
  const double lp = a > 0 ? -(a + std::log1p(std::exp(-a))) : -std::log1p(std::exp(a));
  return static_cast<float>(std::clamp(lp, log_clamp_lo_, log_clamp_hi_));
}

Eigen::Vector3d SurfaceEvidence::Project(const Eigen::Vector3d& x) const {
  // Rows 0 and 1 as ((a + b) + c) + p, row 2 as (a + (b + c)) + p: the order
  // of Eigen's P * x + p for 3x3 doubles with SSE2 (rows 0-1 one packet, row 2
  // a scalar reduction), kept so that fusion results stay those of before.
  const double a0 = P_(0, 0) * x.x(), b0 = P_(0, 1) * x.y(), c0 = P_(0, 2) * x.z();
  const double a1 = P_(1, 0) * x.x(), b1 = P_(1, 1) * x.y(), c1 = P_(1, 2) * x.z();
  const double a2 = P_(2, 0) * x.x(), b2 = P_(2, 1) * x.y(), c2 = P_(2, 2) * x.z();
  return {((a0 + b0) + c0) + p_.x(), ((a1 + b1) + c1) + p_.y(), (a2 + (b2 + c2)) + p_.z()};
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
  const Eigen::Vector3d h = Project(x);
  return FromProjection(h.x(), h.y(), h.z(), log_p, c_out);
}

// FromProjection for nearest sampling without c: Sample and the formulas of
// the general path, with the per-byte tables (inline: the block loop's body).
inline bool SurfaceEvidence::NearestLogP(double h0, double h1, double z, float* log_p) const {
  if (!(z > 1e-9)) return false;
  double u = h0 / z, v = h1 / z;
  if (!(u >= 0 && v >= 0 && u < view_->width() && v < view_->height())) return false;
  const CompactDepthView& m = *view_;
  if (m.block() > 1) {
    u /= m.block();
    v /= m.block();
  }
  const CompactDepthView::Pixel& p = m.at(static_cast<int>(v), static_cast<int>(u));
  if (p.depth == 0 || p.confidence == 0) return false;
  if (CompactDepthView::Label(p) == DepthLabel::kForeground) {
    const double delta = z - m.Depth(p);
    if (delta > band_) return false;
    if (carve_front_ && delta < -margin_) {
      *log_p = free_log_p_[p.confidence];
    } else if (delta * delta <= clamped_within_sq_[p.confidence]) {
      *log_p = static_cast<float>(log_clamp_hi_);
    } else {
      *log_p = LogPOfC(CompactDepthView::Confidence(p) * std::exp(-delta * delta / (2.0 * sigma_v_ * sigma_v_)));
    }
  } else {
    if (z > m.Depth(p)) return false;
    *log_p = free_log_p_[p.confidence];
  }
  return true;
}

bool SurfaceEvidence::FromProjection(double h0, double h1, double z, float* log_p, double* c_out) const {
  if (!bilinear_ && !c_out) return NearestLogP(h0, h1, z, log_p);
  if (!(z > 1e-9)) return false;
  const double u = h0 / z, v = h1 / z;
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
  *log_p = LogPOfC(c);
  if (c_out) *c_out = c;
  return true;
}

void SurfaceEvidence::BlockByVoxel(const BlockCentres& centres, const std::uint64_t active[kBlockDim],
                                   float log_p[kBlockVoxels], std::uint64_t has[kBlockDim]) const {
  for (int i = 0; i < kBlockDim; ++i)
    for (std::uint64_t w = active[i]; w; w &= w - 1) {
      const int b = __builtin_ctzll(w);
      if (LogProbability(Eigen::Vector3d(centres.x[i], centres.y[b >> 3], centres.z[b & 7]), &log_p[i * 64 + b]))
        has[i] |= std::uint64_t{1} << b;
    }
}

void SurfaceEvidence::BlockLogProbability(const BlockCentres& centres, const std::uint64_t active[kBlockDim],
                                          float log_p[kBlockVoxels], std::uint64_t has[kBlockDim]) const {
  constexpr int D = kBlockDim;
  int count = 0;
  for (int i = 0; i < D; ++i) {
    has[i] = 0;
    count += PopCount(active[i]);
  }
  if (count == 0) return;
  if (count >= 8) {
    // The block's 8 corner voxels. Every voxel's projection lies in their
    // convex hull when all are in front of the camera, and its depth is at
    // least theirs: when all lie beyond one image border (1 px margin), or
    // behind every depth (plus the band) of the pixels around their
    // projections, no voxel is seen.
    bool left = true, right = true, top = true, bottom = true;
    double z_min = std::numeric_limits<double>::infinity(), u_min = z_min, v_min = z_min, u_max = -z_min,
           v_max = -z_min;
    for (int q = 0; q < 8; ++q) {
      const int i = (q & 1) * (D - 1), j = ((q >> 1) & 1) * (D - 1), k = ((q >> 2) & 1) * (D - 1);
      const Eigen::Vector3d h = Project(Eigen::Vector3d(centres.x[i], centres.y[j], centres.z[k]));
      if (!(h.z() > 1e-9)) return BlockByVoxel(centres, active, log_p, has);  // straddles the camera plane
      const double u = h.x() / h.z(), v = h.y() / h.z();
      left &= u < -1;
      right &= u > view_->width() + 1;
      top &= v < -1;
      bottom &= v > view_->height() + 1;
      z_min = std::min(z_min, h.z());
      u_min = std::min(u_min, u);
      u_max = std::max(u_max, u);
      v_min = std::min(v_min, v);
      v_max = std::max(v_max, v);
    }
    if (left || right || top || bottom) return;
    if (!bilinear_ && view_->HasTiles()) {  // bilinear depths may lie up to a band behind the nearest pixel's
      const CompactDepthView& m = *view_;
      const double b = m.block();  // stored pixel = floor(u / block), as in FromProjection
      // The stored pixels under [lo, hi] (+-0.01 px for rounding), clamped to [-1, n] before the cast.
      const auto cell = [](double x, int n) { return static_cast<int>(std::clamp(std::floor(x), -1.0, double(n))); };
      const int c0 = std::max(0, cell(u_min / b - 0.01, m.grid_width()));
      const int c1 = std::min(m.grid_width() - 1, cell(u_max / b + 0.01, m.grid_width()));
      const int r0 = std::max(0, cell(v_min / b - 0.01, m.grid_height()));
      const int r1 = std::min(m.grid_height() - 1, cell(v_max / b + 0.01, m.grid_height()));
      if (c0 > c1 || r0 > r1) return;
      std::uint16_t code = 0;
      for (int tr = r0 / CompactDepthView::kTile; tr <= r1 / CompactDepthView::kTile; ++tr)
        for (int tc = c0 / CompactDepthView::kTile; tc <= c1 / CompactDepthView::kTile; ++tc)
          code = std::max(code, m.TileMaxCode(tr, tc));
      if (code == 0) return;  // no pixel there has a depth
      if (code != CompactDepthView::kBeyond) {
        CompactDepthView::Pixel p;
        p.depth = code;
        const double d_max = m.Depth(p);
        if (z_min > d_max + band_ + 1e-9 * (1.0 + d_max)) return;  // every voxel occluded
      }
    }
  }
  // Sparse block: the per-axis terms would cost more than they save.
  if (count < 24) return BlockByVoxel(centres, active, log_p, has);
  // Per-axis products, then the sums of Project in its order: rows 0-1
  // ((a + b) + c) + p with (a + b) per (i, j); row 2 (a + (b + c)) + p with
  // (b + c) per (j, k).
  double a[3][D], bb[3][D], cc[3][D];
  for (int t = 0; t < D; ++t)
    for (int r = 0; r < 3; ++r) {
      a[r][t] = P_(r, 0) * centres.x[t];
      bb[r][t] = P_(r, 1) * centres.y[t];
      cc[r][t] = P_(r, 2) * centres.z[t];
    }
  double bc2[D][D];
  for (int j = 0; j < D; ++j)
    for (int k = 0; k < D; ++k) bc2[j][k] = bb[2][j] + cc[2][k];
  const double p0 = p_.x(), p1 = p_.y(), p2 = p_.z();
  for (int i = 0; i < D; ++i) {
    if (!active[i]) continue;
    double ab0[D], ab1[D];
    for (int j = 0; j < D; ++j) {
      ab0[j] = a[0][i] + bb[0][j];
      ab1[j] = a[1][i] + bb[1][j];
    }
    for (std::uint64_t w = active[i]; w; w &= w - 1) {
      const int b = __builtin_ctzll(w), j = b >> 3, k = b & 7;
      const double h0 = (ab0[j] + cc[0][k]) + p0;
      const double h1 = (ab1[j] + cc[1][k]) + p1;
      const double h2 = (a[2][i] + bc2[j][k]) + p2;
      float* out = &log_p[i * 64 + b];
      if (bilinear_ ? FromProjection(h0, h1, h2, out, nullptr) : NearestLogP(h0, h1, h2, out))
        has[i] |= std::uint64_t{1} << b;
    }
  }
}

}  // namespace lfrecon
