#include "propagation/domain_transform.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "util/error.h"

namespace lfrecon {

DomainTransformFilter::DomainTransformFilter(const cv::Mat& guide, double sigma_spatial, double sigma_color,
                                             int iterations)
    : iterations_(iterations) {
  if (guide.empty() || (guide.type() != CV_32FC1 && guide.type() != CV_32FC3))
    throw OptionError("DomainTransformFilter: the guide must be CV_32FC1 or CV_32FC3");
  LFRECON_CHECK_OPTION(sigma_spatial > 0);
  LFRECON_CHECK_OPTION(sigma_color > 0);
  LFRECON_CHECK_OPTION(iterations >= 1 && iterations <= 10);
  const int rows = guide.rows, cols = guide.cols, ch = guide.channels();
  // σ_H of the first iteration and its feedback coefficient.
  const double sigma_h1 = sigma_spatial * std::sqrt(3.0) * std::pow(2.0, iterations - 1) /
                          std::sqrt(std::pow(4.0, iterations) - 1.0);
  const float log_a = static_cast<float>(-std::sqrt(2.0) / sigma_h1);
  const float ratio = static_cast<float>(sigma_spatial / sigma_color);
  w_hor_.create(rows, cols, CV_32F);
  w_vert_.create(rows, cols, CV_32F);
  // Log-weights first, then one vectorised cv::exp per row.
  tbb::parallel_for(tbb::blocked_range<int>(0, rows), [&](const tbb::blocked_range<int>& range) {
    for (int r = range.begin(); r != range.end(); ++r) {
      const float* g = guide.ptr<float>(r);
      const float* up = r > 0 ? guide.ptr<float>(r - 1) : nullptr;
      float* wh = w_hor_.ptr<float>(r);
      float* wv = w_vert_.ptr<float>(r);
      wh[0] = -1e30f;  // exp → 0: column 0 has no left neighbour
      for (int c = 1; c < cols; ++c) {
        float d = 0;
        for (int k = 0; k < ch; ++k) d += std::abs(g[c * ch + k] - g[(c - 1) * ch + k]);
        wh[c] = log_a * (1.0f + ratio * d);
      }
      for (int c = 0; c < cols; ++c) {
        float d = 0;
        if (up)
          for (int k = 0; k < ch; ++k) d += std::abs(g[c * ch + k] - up[c * ch + k]);
        wv[c] = up ? log_a * (1.0f + ratio * d) : -1e30f;
      }
      cv::Mat hrow = w_hor_.row(r), vrow = w_vert_.row(r);
      cv::exp(hrow, hrow);
      cv::exp(vrow, vrow);
    }
  });
}

namespace {

// The horizontal sweeps (left to right, then back) of rows [r0, r0 + R), in
// lockstep: each pixel's update waits on its neighbour's (sub, mul, add), so
// one row alone leaves the core idle on that chain; R rows give R chains.
// The arithmetic per element is the same as one row at a time.
template <int N, int R>
void HorizontalSweeps(cv::Mat& data, const cv::Mat& wh, int n, int r0) {
  const int cols = data.cols;
  float* row[R];
  const float* w[R];
  for (int i = 0; i < R; ++i) row[i] = data.ptr<float>(r0 + i), w[i] = wh.ptr<float>(r0 + i);
  for (int c = 1; c < cols; ++c)
    for (int i = 0; i < R; ++i) {
      const float a = w[i][c];
      float* cur = row[i] + c * n;
      const float* prev = cur - n;
      for (int k = 0; k < (N > 0 ? N : n); ++k) cur[k] += a * (prev[k] - cur[k]);
    }
  for (int c = cols - 2; c >= 0; --c)
    for (int i = 0; i < R; ++i) {
      const float a = w[i][c + 1];
      float* cur = row[i] + c * n;
      const float* next = cur + n;
      for (int k = 0; k < (N > 0 ? N : n); ++k) cur[k] += a * (next[k] - cur[k]);
    }
}

// The four recursive sweeps of one iteration over `data` with N channels
// (N > 0 fixed at compile time so the per-pixel channel loops unroll and
// vectorise; N == 0: runtime channel count `n`).
template <int N>
void Sweeps(cv::Mat& data, const cv::Mat& wh, const cv::Mat& wv, int n_runtime) {
  const int n = N > 0 ? N : n_runtime;
  const int rows = data.rows, cols = data.cols;
  // Horizontal: rows are independent; four at a time (HorizontalSweeps).
  constexpr int kRows = 4;
  tbb::parallel_for(tbb::blocked_range<int>(0, (rows + kRows - 1) / kRows), [&](const tbb::blocked_range<int>& range) {
    for (int g = range.begin(); g != range.end(); ++g) {
      const int r0 = g * kRows;
      if (r0 + kRows <= rows)
        HorizontalSweeps<N, kRows>(data, wh, n, r0);
      else
        for (int r = r0; r < rows; ++r) HorizontalSweeps<N, 1>(data, wh, n, r);
    }
  });
  // Vertical: column blocks are independent; rows are walked in order, so
  // the inner loops run over contiguous memory. A block is 64 columns: with
  // 16 (768 bytes of 12 channels per row) every row of a block was a new 4 KiB
  // page, and the sweeps waited on TLB misses (1280x720x12: 55.8 -> 30-34 ms per
  // filter on 2 threads with the horizontal lockstep; 128 columns is as fast
  // at 720p but leaves 2 threads 5 blocks at 640 wide).
  const int block = 64;
  tbb::parallel_for(tbb::blocked_range<int>(0, (cols + block - 1) / block), [&](const tbb::blocked_range<int>& range) {
    for (int b = range.begin(); b != range.end(); ++b) {
      const int c0 = b * block, c1 = std::min(cols, c0 + block);
      for (int r = 1; r < rows; ++r) {
        float* cur = data.ptr<float>(r) + c0 * n;
        const float* prev = data.ptr<float>(r - 1) + c0 * n;
        const float* w = wv.ptr<float>(r);
        for (int c = c0; c < c1; ++c, cur += n, prev += n) {
          const float a = w[c];
          for (int k = 0; k < n; ++k) cur[k] += a * (prev[k] - cur[k]);
        }
      }
      for (int r = rows - 2; r >= 0; --r) {
        float* cur = data.ptr<float>(r) + c0 * n;
        const float* next = data.ptr<float>(r + 1) + c0 * n;
        const float* w = wv.ptr<float>(r + 1);
        for (int c = c0; c < c1; ++c, cur += n, next += n) {
          const float a = w[c];
          for (int k = 0; k < n; ++k) cur[k] += a * (next[k] - cur[k]);
        }
      }
    }
  });
}

}  // namespace

void DomainTransformFilter::Apply(cv::Mat& data) const {
  if (data.depth() != CV_32F || data.rows != w_hor_.rows || data.cols != w_hor_.cols)
    throw OptionError("DomainTransformFilter: data must be CV_32F with the guide's size");
  if (!data.isContinuous()) data = data.clone();
  const int n = data.channels();
  cv::Mat wh = w_hor_.clone(), wv = w_vert_.clone();
  for (int it = 0; it < iterations_; ++it) {
    if (it > 0) {  // a_i = a_{i−1}²: σ_H halves from one iteration to the next
      cv::multiply(wh, wh, wh);
      cv::multiply(wv, wv, wv);
    }
    switch (n) {
      case 1: Sweeps<1>(data, wh, wv, n); break;
      case 2: Sweeps<2>(data, wh, wv, n); break;
      case 4: Sweeps<4>(data, wh, wv, n); break;
      case 11: Sweeps<11>(data, wh, wv, n); break;
      case 12: Sweeps<12>(data, wh, wv, n); break;
      default: Sweeps<0>(data, wh, wv, n); break;
    }
  }
}

}  // namespace lfrecon
