#pragma once
// Analytic ray casting of a synth::Scene into one pinhole view: an
// antialiased colour image (S x S supersampling), exact planar depth and the
// primitive id at each pixel centre (COLMAP convention: pixel (c, r) has its
// centre at (c + 0.5, r + 0.5)), and optional per-channel Gaussian noise.
// Everything is a pure function of (scene, view, options, noise_seed): the
// same inputs give bit-identical outputs however many threads run.
#include <Eigen/Core>
#include <cstdint>
#include <opencv2/core.hpp>

#include "geometry/pinhole_view.h"
#include "synth/scene.h"

namespace lfrecon::synth {

struct RenderOptions {
  // S x S samples per pixel on a regular grid ((k + 0.5) / S); odd S puts one
  // sample on the pixel centre, which then also gives depth and label.
  int supersampling = 3;
  // Stratified jitter of the samples inside their cells (seeded per frame).
  bool jitter = false;
  // Pre-filter the solid textures to each sample's footprint on the surface
  // (Material::Albedo's `filter`): detail finer than a sample fades to its
  // mean instead of aliasing, at any distance or slant.
  bool texture_filter = true;
  // Pixels whose S x S samples all hit the same primitive take one texture
  // value at the pixel centre, filtered over the whole pixel footprint; pixels
  // on silhouettes and occlusion edges always average all samples, which is
  // what the antialiased edges need. Needs texture_filter; several times faster
  // than filtering every sample. false: every pixel averages all samples.
  bool adaptive = true;
  // Standard deviation of the additive Gaussian noise per channel, colours in [0, 1].
  double noise_sigma = 0.01;
  // Round colours to 8-bit levels, so frames equal what a PNG round trip gives.
  bool quantize = false;

  void Check() const;  // throws OptionError
};

struct RenderResult {
  cv::Mat image;   // CV_32FC3, BGR, [0, 1]
  cv::Mat depth;   // CV_64F planar depth (camera z, metres) at pixel centres; 0 where no surface is hit
  cv::Mat labels;  // CV_32S primitive id seen at pixel centres; -1 where none
  cv::Mat mixed;   // CV_8U, 255 where the pixel's samples hit different primitives (silhouettes, occlusions)
};

RenderResult Render(const Scene& scene, const PinholeView& view, const RenderOptions& options,
                    std::uint64_t noise_seed);

// The ray through image point `pixel` (COLMAP coordinates, any sub-pixel
// position): nearest hit; hit.t is the planar depth in `view`.
Hit CastPixel(const Scene& scene, const PinholeView& view, const Eigen::Vector2d& pixel);

// CV_8U masks (255 = yes) from a label map: pixels showing a foreground / thin primitive.
cv::Mat ForegroundMask(const Scene& scene, const cv::Mat& labels);
cv::Mat ThinMask(const Scene& scene, const cv::Mat& labels);

// Depth converted to the io convention (CV_32F, 0 = none), e.g. for WriteExr.
cv::Mat DepthToFloat(const cv::Mat& depth);

}  // namespace lfrecon::synth
