#include "propagation/depth_propagator.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <opencv2/imgproc.hpp>
#include <opencv2/ximgproc/edge_filter.hpp>

#include "propagation/domain_transform.h"
#include "util/error.h"
#include "util/progress.h"
#include "util/scratch_pool.h"

namespace lfrecon {

void PropagationOptions::Check() const {
  photo.Check();
  consistency.Check();
  refinement.Check();
  LFRECON_CHECK_OPTION(dt_sigma_spatial > 0 && dt_sigma_spatial <= 1);
  LFRECON_CHECK_OPTION(dt_sigma_color > 0);
  LFRECON_CHECK_OPTION(dt_mode == DomainTransformMode::kNormalizedConvolution ||
                       dt_mode == DomainTransformMode::kInterpolatedConvolution ||
                       dt_mode == DomainTransformMode::kRecursive || dt_mode == DomainTransformMode::kOwnRecursive);
  LFRECON_CHECK_OPTION(model == PropagationModel::kConstant || model == PropagationModel::kAffine);
  LFRECON_CHECK_OPTION(affine_ridge_px >= 0);
  LFRECON_CHECK_OPTION(dt_iterations >= 1 && dt_iterations <= 10);
  LFRECON_CHECK_OPTION(guide_sigma >= 0 && guide_sigma <= 10);
  LFRECON_CHECK_OPTION(min_filtered_confidence >= 0 && min_filtered_confidence < 1);
  LFRECON_CHECK_OPTION(extrapolation_m0 >= 0);
  LFRECON_CHECK_OPTION(extrapolation_floor_px > 0);
}

PropagationOptions PaperPropagationOptions() {
  PropagationOptions o;
  o.model = PropagationModel::kConstant;
  o.dt_mode = DomainTransformMode::kNormalizedConvolution;
  o.weight_by_depth_confidence = false;
  o.one_sided_silhouettes = false;
  o.silhouette_pixels_splat_only = false;
  o.blocked_silhouettes_keep_depth = false;
  o.keep_edge_depths = false;
  o.keep_contested_foreground = false;
  o.filter_inverse_depth = false;
  o.consistency.views = 0;
  o.photo.centre_consistency = false;
  o.extrapolation_m0 = 0;
  return o;
}

DepthPropagator::DepthPropagator(const PropagationOptions& options) : options_(options) { options_.Check(); }

namespace {

constexpr std::uint8_t kFg = static_cast<std::uint8_t>(DepthLabel::kForeground);
constexpr std::uint8_t kBg = static_cast<std::uint8_t>(DepthLabel::kBackground);

// The integer step to the neighbour pixel of p in direction (cos θ, sin θ).
inline cv::Point NeighborStep(const cv::Vec2f& n) {
  return cv::Point(static_cast<int>(std::lround(n[0])), static_cast<int>(std::lround(n[1])));
}

}  // namespace

SplatMaps SplatMaps::Zeros(int rows, int cols) {
  SplatMaps s;
  s.depth_fg = cv::Mat::zeros(rows, cols, CV_32F);
  s.confidence_fg = cv::Mat::zeros(rows, cols, CV_32F);
  s.depth_bg = cv::Mat::zeros(rows, cols, CV_32F);
  s.confidence_bg = cv::Mat::zeros(rows, cols, CV_32F);
  s.edge_label = cv::Mat::zeros(rows, cols, CV_8U);
  s.edge_depth = cv::Mat::zeros(rows, cols, CV_32F);
  return s;
}

SplatMaps DepthPropagator::Splat(const DepthMap& filtered, const EdgeConsistency& edges) const {
  const int rows = filtered.depth.rows, cols = filtered.depth.cols;
  SplatMaps s = SplatMaps::Zeros(rows, cols);
  if (filtered.depth.empty() || edges.evaluated.size() != filtered.depth.size() ||
      filtered.label.size() != filtered.depth.size())
    return s;
  const bool weight = options_.weight_by_depth_confidence && filtered.confidence.size() == filtered.depth.size() &&
                      filtered.confidence.type() == CV_32F;
  // An edge pixel: evaluated by the photoconsistency stage, with a side label.
  auto is_edge = [&](int r, int c) {
    const std::uint8_t l = filtered.label.at<std::uint8_t>(r, c);
    return edges.evaluated.at<std::uint8_t>(r, c) && filtered.depth.at<float>(r, c) > 0 && (l == kFg || l == kBg);
  };
  auto scale = [&](int r, int c) { return weight ? filtered.confidence.at<float>(r, c) : 1.0f; };
  const bool one_sided = options_.one_sided_silhouettes;
  const bool silhouette_splat_only = options_.silhouette_pixels_splat_only;
  const float ratio = static_cast<float>(options_.photo.silhouette_ratio);
  cv::Mat is_edge_map = cv::Mat::zeros(rows, cols, CV_8U);
  tbb::parallel_for(tbb::blocked_range<int>(0, rows), [&](const tbb::blocked_range<int>& range) {
    for (int r = range.begin(); r != range.end(); ++r)
      for (int c = 0; c < cols; ++c)
        if (is_edge(r, c)) is_edge_map.at<std::uint8_t>(r, c) = 1;
  });
  const bool keep_blocked = options_.blocked_silhouettes_keep_depth;
  const bool has_centre = edges.c_centre.size() == filtered.depth.size() && edges.c_centre.type() == CV_32F;
  if (has_centre) s.thin_confidence = cv::Mat::zeros(rows, cols, CV_32F);
  // The pixel a silhouette edge pixel splats to (its consistent side).
  const auto consistent_target = [&](int r, int c) {
    const cv::Point step = NeighborStep(edges.direction.at<cv::Vec2f>(r, c));
    const bool plus = edges.c_plus.at<float>(r, c) >= edges.c_minus.at<float>(r, c);
    return plus ? cv::Point(c + step.x, r + step.y) : cv::Point(c - step.x, r - step.y);
  };
  const auto silhouette = [&](int r, int c) {
    const float cp = edges.c_plus.at<float>(r, c), cm = edges.c_minus.at<float>(r, c);
    return std::abs(cp - cm) > ratio * (cp + cm);
  };
  // Two silhouette edge pixels of one label that splat into each other: the
  // two sides of a part two pixels wide (or one pixel on a diagonal).
  const auto silhouette_pair = [&](int r, int c) {
    const cv::Point t = consistent_target(r, c);
    if (t.x < 0 || t.y < 0 || t.x >= cols || t.y >= rows || !is_edge_map.at<std::uint8_t>(t.y, t.x)) return false;
    if (filtered.label.at<std::uint8_t>(t.y, t.x) != filtered.label.at<std::uint8_t>(r, c) || !silhouette(t.y, t.x))
      return false;
    return consistent_target(t.y, t.x) == cv::Point(c, r);
  };
  // 1. Edge pixels keep their depth with max(C+, C−) (§4.2); rows in parallel.
  tbb::parallel_for(tbb::blocked_range<int>(0, rows), [&](const tbb::blocked_range<int>& range) {
    for (int r = range.begin(); r != range.end(); ++r)
      for (int c = 0; c < cols; ++c) {
        if (!is_edge_map.at<std::uint8_t>(r, c)) continue;
        const float cp = edges.c_plus.at<float>(r, c), cm = edges.c_minus.at<float>(r, c);
        float conf = scale(r, c) * std::max(cp, cm);
        const float d = filtered.depth.at<float>(r, c);
        const std::uint8_t l = filtered.label.at<std::uint8_t>(r, c);
        s.edge_label.at<std::uint8_t>(r, c) = l;
        s.edge_depth.at<float>(r, c) = d;
        // Silhouette pixels feed the filter only through their splat on the
        // consistent side, unless (blocked_silhouettes_keep_depth) the pixel
        // and its target are a pair that splat into each other: then it keeps
        // its own depth, else the part would reach the filter nowhere.
        if (silhouette_splat_only && silhouette(r, c) && !(keep_blocked && silhouette_pair(r, c))) conf = 0;
        // A part one or two pixels wide (PhotoconsistencyOptions::centre_consistency):
        // its depth holds along the edge (C0) better than on either side of
        // it, which both see what lies behind; it keeps its depth with C0.
        if (has_centre) {
          const float c0 = edges.c_centre.at<float>(r, c);
          const float side = std::max(cp, cm);
          // Clearly better along than across, by the silhouette test's own
          // ratio (Fig. 4). Kept after the filter, not fed to it: as a source
          // it would spread the part's depth over the pixels beside it.
          if (l == kFg && c0 - side > ratio * (c0 + side)) s.thin_confidence.at<float>(r, c) = scale(r, c) * c0;
        }
        if (!(conf > 0)) continue;
        (l == kFg ? s.depth_fg : s.depth_bg).at<float>(r, c) = d;
        (l == kFg ? s.confidence_fg : s.confidence_bg).at<float>(r, c) = conf;
      }
  });
  // 2. The splat: the +θ neighbour of p gets C+(p), the −θ neighbour C−(p);
  // edge pixels are not overwritten; conflicts go to the highest confidence
  // (§4.2). Serial in raster order over the edge pixels (a few percent of the
  // image): cheap, and the winner of a tie is the first in raster order.
  cv::Mat best_c(rows, cols, CV_32F, cv::Scalar(0.0f)), best_d(rows, cols, CV_32F, cv::Scalar(0.0f));
  cv::Mat best_l = cv::Mat::zeros(rows, cols, CV_8U);
  for (int r = 0; r < rows; ++r) {
    const std::uint8_t* edge_row = is_edge_map.ptr<std::uint8_t>(r);
    for (int c = 0; c < cols; ++c) {
      if (!edge_row[c]) continue;
      const cv::Point step = NeighborStep(edges.direction.at<cv::Vec2f>(r, c));
      const float cp = edges.c_plus.at<float>(r, c), cm = edges.c_minus.at<float>(r, c);
      // One-sided at silhouettes: the less consistent side gets nothing.
      const bool silhouette = one_sided && std::abs(cp - cm) > ratio * (cp + cm);
      const float k = scale(r, c);
      for (int side = 0; side < 2; ++side) {
        const float cand = side == 0 ? cp : cm;
        if (silhouette && cand < std::max(cp, cm)) continue;
        const int tr = side == 0 ? r + step.y : r - step.y, tc = side == 0 ? c + step.x : c - step.x;
        if (tr < 0 || tc < 0 || tr >= rows || tc >= cols || is_edge_map.at<std::uint8_t>(tr, tc)) continue;
        float& bc = best_c.at<float>(tr, tc);
        if (k * cand > bc) {
          bc = k * cand;
          best_d.at<float>(tr, tc) = filtered.depth.at<float>(r, c);
          best_l.at<std::uint8_t>(tr, tc) = filtered.label.at<std::uint8_t>(r, c);
        }
      }
    }
  }
  tbb::parallel_for(tbb::blocked_range<int>(0, rows), [&](const tbb::blocked_range<int>& range) {
    for (int r = range.begin(); r != range.end(); ++r) {
      const float* bc = best_c.ptr<float>(r);
      for (int c = 0; c < cols; ++c) {
        if (!(bc[c] > 0)) continue;
        const bool fg = best_l.at<std::uint8_t>(r, c) == kFg;
        (fg ? s.depth_fg : s.depth_bg).at<float>(r, c) = best_d.at<float>(r, c);
        (fg ? s.confidence_fg : s.confidence_bg).at<float>(r, c) = bc[c];
      }
    }
  });
  return s;
}

DepthMap DepthPropagator::Filter(const cv::Mat& image, const SplatMaps& splats) const {
  const PropagationOptions& o = options_;
  const int rows = splats.depth_fg.rows, cols = splats.depth_fg.cols;
  DepthMap out(rows, cols);
  if (rows == 0 || cols == 0 || image.size() != splats.depth_fg.size() || image.type() != CV_32FC3) return out;
  const bool inv = o.filter_inverse_depth;
  // The filtered quantity: depth, or inverse depth (see the options).
  const auto q = [inv](float d) { return inv ? 1.0 / d : static_cast<double>(d); };
  // Per-side reference value: the confidence-weighted mean (see header).
  double ref[2] = {0, 0}, total_conf[2] = {0, 0};
  const cv::Mat* depth_of[2] = {&splats.depth_fg, &splats.depth_bg};
  const cv::Mat* conf_of[2] = {&splats.confidence_fg, &splats.confidence_bg};
  for (int side = 0; side < 2; ++side) {
    double sw = 0, swd = 0;
    for (int r = 0; r < rows; ++r) {
      const float* d = depth_of[side]->ptr<float>(r);
      const float* w = conf_of[side]->ptr<float>(r);
      for (int c = 0; c < cols; ++c)
        if (w[c] > 0) {
          sw += w[c];
          swd += w[c] * q(d[c]);
        }
    }
    total_conf[side] = sw;
    ref[side] = sw > 0 ? swd / sw : 0;
  }
  if (!(total_conf[0] > 0) && !(total_conf[1] > 0)) return out;  // nothing to propagate

  cv::Mat guide = image;
  if (o.guide_sigma > 0) cv::GaussianBlur(image, guide, cv::Size(0, 0), o.guide_sigma);
  const double sigma_spatial = std::max(1.0, o.dt_sigma_spatial * cols);
  const bool affine = o.model == PropagationModel::kAffine;
  // Channels. Constant model (eq. 10): C_fg·z_fg, C_fg, C_bg·z_bg, C_bg.
  // Affine model (ours), foreground: C, C·u, C·v, C·u², C·u·v, C·v², C·z, C·u·z, C·v·z,
  // then C_bg·z_bg, C_bg; z = value − side reference, (u, v) pixel coordinates / scale.
  const int n = affine ? 12 : 4;  // affine: 11 used, padded to 12 (whole SIMD vectors)
  const int bg0 = affine ? 9 : 2;
  const double scale = 0.5 * cols;
  const auto U = [&](int c) { return static_cast<float>((c + 0.5 - 0.5 * cols) / scale); };
  const auto V = [&](int r) { return static_cast<float>((r + 0.5 - 0.5 * rows) / scale); };
  // The channels are 44 MiB at 720p: kept from one view to the next (ScratchPool).
  static ScratchPool channel_buffers;
  const ScratchPool::Lease lease =
      channel_buffers.Acquire(static_cast<std::size_t>(rows) * static_cast<std::size_t>(cols) * n * sizeof(float));
  cv::Mat data(rows, cols, CV_32FC(n), lease.data());
  tbb::parallel_for(tbb::blocked_range<int>(0, rows), [&](const tbb::blocked_range<int>& range) {
    for (int r = range.begin(); r != range.end(); ++r) {
      float* s = data.ptr<float>(r);
      std::fill(s, s + static_cast<std::ptrdiff_t>(cols) * n, 0.0f);  // the pool's block is not zeroed
      const float *df = splats.depth_fg.ptr<float>(r), *cf = splats.confidence_fg.ptr<float>(r);
      const float *db = splats.depth_bg.ptr<float>(r), *cb = splats.confidence_bg.ptr<float>(r);
      const float v = V(r);
      for (int c = 0; c < cols; ++c, s += n) {
        if (cf[c] > 0) {
          const float w = cf[c], zf = static_cast<float>(q(df[c]) - ref[0]);
          if (affine) {
            const float u = U(c);
            s[0] = w;
            s[1] = w * u;
            s[2] = w * v;
            s[3] = w * u * u;
            s[4] = w * u * v;
            s[5] = w * v * v;
            s[6] = w * zf;
            s[7] = w * u * zf;
            s[8] = w * v * zf;
          } else {
            s[0] = w * zf;
            s[1] = w;
          }
        }
        if (cb[c] > 0) {
          s[bg0] = cb[c] * static_cast<float>(q(db[c]) - ref[1]);
          s[bg0 + 1] = cb[c];
        }
      }
    }
  });
  if (affine || o.dt_mode == DomainTransformMode::kOwnRecursive) {
    DomainTransformFilter(guide, sigma_spatial, o.dt_sigma_color, o.dt_iterations).Apply(data);
  } else {
    const int mode = o.dt_mode == DomainTransformMode::kRecursive                  ? cv::ximgproc::DTF_RF
                     : o.dt_mode == DomainTransformMode::kInterpolatedConvolution ? cv::ximgproc::DTF_IC
                                                                                  : cv::ximgproc::DTF_NC;
    cv::Ptr<cv::ximgproc::DTFilter> dt =
        cv::ximgproc::createDTFilter(guide, sigma_spatial, o.dt_sigma_color, mode, o.dt_iterations);
    cv::Mat filtered;
    dt->filter(data, filtered);
    data = filtered;
  }

  const float min_conf = static_cast<float>(o.min_filtered_confidence);
  // Ridge on the slopes of the affine fit, in (u, v) units (see the options).
  const float ridge = static_cast<float>(std::pow(o.affine_ridge_px / scale, 2));
  const bool extrap_on = affine && o.extrapolation_m0 > 0;
  const bool keep_contested = o.keep_contested_foreground;
  const float contested_ratio = static_cast<float>(o.photo.silhouette_ratio);
  const bool has_thin = splats.thin_confidence.size() == splats.edge_depth.size() &&
                        splats.thin_confidence.type() == CV_32F;
  const double floor2 = std::pow(o.extrapolation_floor_px / scale, 2);
  tbb::parallel_for(tbb::blocked_range<int>(0, rows), [&](const tbb::blocked_range<int>& range) {
    for (int r = range.begin(); r != range.end(); ++r) {
      const float* f = data.ptr<float>(r);
      float* depth = out.depth.ptr<float>(r);
      float* conf = out.confidence.ptr<float>(r);
      std::uint8_t* label = out.label.ptr<std::uint8_t>(r);
      const float vq = V(r);
      const float* thin = has_thin ? splats.thin_confidence.ptr<float>(r) : nullptr;
      for (int c = 0; c < cols; ++c, f += n) {
        if (thin && thin[c] > 0) {  // a part one or two pixels wide keeps its own depth and side
          depth[c] = splats.edge_depth.at<float>(r, c);
          conf[c] = thin[c];
          label[c] = splats.edge_label.at<std::uint8_t>(r, c);
          continue;
        }
        float cfg = std::max(0.0f, f[affine ? 0 : 1]);
        const float cbg = std::max(0.0f, f[bg0 + 1]);
        // The foreground fit's moments (kAffine), for the extrapolation test and the plane.
        float mu = 0, mv = 0, mz = 0, suu0 = 0, svv0 = 0, suv = 0, suz = 0, svz = 0;
        double slope_u = 0, slope_v = 0;
        if (affine && cfg > min_conf) {
          const float iw = 1.0f / cfg;
          mu = f[1] * iw, mv = f[2] * iw, mz = f[6] * iw;
          suu0 = std::max(0.0f, f[3] * iw - mu * mu);
          svv0 = std::max(0.0f, f[5] * iw - mv * mv);
          suv = f[4] * iw - mu * mv;
          suz = f[7] * iw - mu * mz, svz = f[8] * iw - mv * mz;
          const float suu = suu0 + ridge, svv = svv0 + ridge;
          const float det = suu * svv - suv * suv;
          if (det > 0) {
            slope_u = (svv * suz - suv * svz) / det;
            slope_v = (suu * svz - suv * suz) / det;
          }
          const double du = U(c) - mu, dv = vq - mv;
          if (extrap_on && splats.edge_label.at<std::uint8_t>(r, c) != kFg) {
            // Mahalanobis distance of the pixel from its support's weighted
            // centroid, the support's spread floored at extrapolation_floor_px
            // (a line of support is not a zero-width one); pixels with a
            // foreground depth of their own are exempt.
            const double eu = suu0 + floor2, ev = svv0 + floor2;
            const double m2 = (ev * du * du - 2 * suv * du * dv + eu * dv * dv) / std::max(eu * ev - suv * suv, 1e-30);
            const double excess = std::max(0.0, std::sqrt(std::max(0.0, m2)) - o.extrapolation_m0);
            cfg *= static_cast<float>(std::exp(-0.5 * excess * excess));
          }
        }
        bool fg = cfg >= cbg;  // the side with the larger filtered confidence
        const std::uint8_t own = splats.edge_label.at<std::uint8_t>(r, c);
        // A foreground edge pixel that the background wins only narrowly (not
        // by the silhouette ratio) keeps its own depth and side, with full
        // confidence, even where both sides reached it only faintly
        // (PropagationOptions::keep_contested_foreground).
        const bool contested = keep_contested && own == kFg && !fg && cbg - cfg <= contested_ratio * (cbg + cfg);
        if (contested) fg = true;
        const float cw = fg ? cfg : cbg;
        if (!(cw > min_conf) && !contested) continue;
        double d;
        if (o.keep_edge_depths && own == (fg ? kFg : kBg)) {
          d = splats.edge_depth.at<float>(r, c);
        } else {
          // D' = (C ⊙ D)' / C' (eq. 10), plus the side's reference value.
          double value;
          if (!fg) {
            value = ref[1] + f[bg0] / cw;
          } else if (!affine) {
            value = ref[0] + f[0] / cw;
          } else {
            // Confidence-weighted least-squares plane through the filtered
            // moments, with a ridge on its slopes, evaluated at this pixel
            // (moments computed above).
            value = ref[0] + mz + slope_u * (U(c) - mu) + slope_v * (vq - mv);
          }
          d = inv ? 1.0 / value : value;
        }
        if (!(d > 0) || !std::isfinite(d)) continue;
        depth[c] = static_cast<float>(d);
        conf[c] = contested ? 1.0f : std::abs(cfg - cbg);  // |C'_fg − C'_bg| (§4.2), contested: see above
        label[c] = fg ? kFg : kBg;
      }
    }
  });
  return out;
}

bool DepthPropagator::ValidInput(const ViewImage& reference, const DepthMap& filtered) {
  return reference.image.rows > 0 && reference.image.cols > 0 && reference.image.type() == CV_32FC3 &&
         filtered.depth.size() == reference.image.size() && filtered.depth.type() == CV_32F;
}

DepthMap DepthPropagator::LabelFromVolume(const PinholeView& view, const DepthMap& filtered, const BoundingBox& volume) {
  const int rows = filtered.depth.rows, cols = filtered.depth.cols;
  DepthMap labelled;
  labelled.depth = filtered.depth;
  labelled.confidence = filtered.confidence;
  labelled.label = filtered.label.size() == filtered.depth.size() && filtered.label.type() == CV_8U
                       ? filtered.label.clone()
                       : cv::Mat::zeros(rows, cols, CV_8U);
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) {
      std::uint8_t& l = labelled.label.at<std::uint8_t>(r, c);
      const float d = labelled.depth.at<float>(r, c);
      if (l != kFg && l != kBg && d > 0)
        l = volume.Contains(view.Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), d)) ? kFg : kBg;
    }
  return labelled;
}

DenseDepthResult DepthPropagator::Run(const ViewImage& reference, const std::vector<const ViewImage*>& neighbors,
                                      const DepthMap& filtered, const BoundingBox& volume) const {
  DenseDepthResult result;
  const int rows = reference.image.rows, cols = reference.image.cols;
  result.dense = DepthMap(rows, cols);
  if (!ValidInput(reference, filtered)) {
    result.edges.c_plus = cv::Mat::zeros(rows, cols, CV_32F);
    result.edges.c_minus = cv::Mat::zeros(rows, cols, CV_32F);
    result.edges.direction = cv::Mat::zeros(rows, cols, CV_32FC2);
    result.edges.evaluated = cv::Mat::zeros(rows, cols, CV_8U);
    return result;
  }
  const DepthMap labelled = LabelFromVolume(reference.view, filtered, volume);

  Timer timer;
  result.edges = BidirectionalPhotoconsistency(options_.photo).Compute(reference, neighbors, labelled);
  result.seconds_photoconsistency = timer.Seconds();
  timer.Restart();
  const SplatMaps splats = Splat(labelled, result.edges);
  result.seconds_splat = timer.Seconds();
  timer.Restart();
  result.dense = Filter(reference.image, splats);
  result.seconds_filter = timer.Seconds();
  timer.Restart();
  CheckDenseConsistency(reference, neighbors, options_.consistency, &result.dense, labelled.depth);
  result.seconds_consistency = timer.Seconds();
  timer.Restart();
  RefineDepthPhotometrically(reference, neighbors, options_.refinement, &result.dense, labelled.depth);
  result.seconds_refinement = timer.Seconds();
  return result;
}

DepthMap DensifyDepth(const ViewImage& reference, const std::vector<const ViewImage*>& neighbors,
                      const DepthMap& filtered, const BoundingBox& volume, const PropagationOptions& options) {
  return DepthPropagator(options).Run(reference, neighbors, filtered, volume).dense;
}

}  // namespace lfrecon
