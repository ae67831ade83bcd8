#include "fusion/mesh_coloring.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "util/error.h"

namespace lfrecon {
namespace {

// Bilinear colour at (u, v) over the neighbouring pixels whose visible depth
// is the point's own (planar depth z, within the tolerance): at occlusion
// boundaries and silhouettes the pixels of other surfaces are left out.
// Returns false when none is left.
bool SampleVisibleBgr(const cv::Mat& image, const cv::Mat& depth, double u, double v, double z, double tolerance,
                      Eigen::Vector3d* bgr) {
  const double x = u - 0.5, y = v - 0.5;
  const int c0 = static_cast<int>(std::floor(x)), r0 = static_cast<int>(std::floor(y));
  const double fx = x - c0, fy = y - r0;
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  double wsum = 0;
  for (int k = 0; k < 4; ++k) {
    const int r = std::clamp(r0 + (k >> 1), 0, image.rows - 1), c = std::clamp(c0 + (k & 1), 0, image.cols - 1);
    const float d = depth.at<float>(r, c);
    if (!(d > 0) || std::abs(z - d) > tolerance) continue;
    const double w = ((k & 1) ? fx : 1 - fx) * ((k >> 1) ? fy : 1 - fy);
    if (w <= 0) continue;
    Eigen::Vector3d p;
    if (image.type() == CV_32FC3) {
      const cv::Vec3f q = image.at<cv::Vec3f>(r, c);
      p = Eigen::Vector3d(q[0], q[1], q[2]);
    } else {
      const cv::Vec3b q = image.at<cv::Vec3b>(r, c);
      p = Eigen::Vector3d(q[0], q[1], q[2]) / 255.0;
    }
    sum += w * p;
    wsum += w;
  }
  if (wsum <= 1e-9) return false;
  *bgr = sum / wsum;
  return true;
}

}  // namespace

void ColoringOptions::Check() const {
  LFRECON_CHECK_OPTION(depth_tolerance >= 0);
  LFRECON_CHECK_OPTION(min_cos >= 0 && min_cos < 1);
}

cv::Mat RenderMeshDepth(const TriangleMesh& mesh, const PinholeView& view) {
  cv::Mat depth(view.height, view.width, CV_32F, cv::Scalar(0));
  std::vector<Eigen::Vector3d> cam(mesh.vertices.size());
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) cam[i] = view.R * mesh.vertices[i].cast<double>() + view.t;
  for (const Eigen::Vector3i& t : mesh.triangles) {
    Eigen::Vector3d z, u, v;
    bool ok = true;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d& x = cam[t[k]];
      if (x.z() <= 1e-6) {
        ok = false;
        break;
      }
      const Eigen::Vector3d h = view.K * x;
      z[k] = x.z();
      u[k] = h.x() / h.z();
      v[k] = h.y() / h.z();
    }
    if (!ok) continue;
    const double area = (u[1] - u[0]) * (v[2] - v[0]) - (u[2] - u[0]) * (v[1] - v[0]);
    if (std::abs(area) < 1e-12) continue;
    const int c0 = std::max(0, static_cast<int>(std::ceil(u.minCoeff() - 0.5)));
    const int c1 = std::min(view.width - 1, static_cast<int>(std::floor(u.maxCoeff() - 0.5)));
    const int r0 = std::max(0, static_cast<int>(std::ceil(v.minCoeff() - 0.5)));
    const int r1 = std::min(view.height - 1, static_cast<int>(std::floor(v.maxCoeff() - 0.5)));
    for (int r = r0; r <= r1; ++r) {
      float* row = depth.ptr<float>(r);
      const double py = r + 0.5;
      for (int c = c0; c <= c1; ++c) {
        const double px = c + 0.5;
        const double b0 = ((u[1] - px) * (v[2] - py) - (u[2] - px) * (v[1] - py)) / area;
        const double b1 = ((u[2] - px) * (v[0] - py) - (u[0] - px) * (v[2] - py)) / area;
        const double b2 = 1 - b0 - b1;
        if (b0 < 0 || b1 < 0 || b2 < 0) continue;
        const double zz = 1.0 / (b0 / z[0] + b1 / z[1] + b2 / z[2]);  // perspective-correct
        if (row[c] == 0 || zz < row[c]) row[c] = static_cast<float>(zz);
      }
    }
  }
  return depth;
}

void ColorizeMesh(TriangleMesh* mesh, const std::vector<ColorView>& views, const ColoringOptions& options) {
  options.Check();
  if (!mesh->HasNormals()) mesh->ComputeVertexNormals();
  const std::size_t n = mesh->vertices.size();
  std::vector<Eigen::Vector3d> sum(n, Eigen::Vector3d::Zero());
  std::vector<double> weight(n, 0.0);
  for (const ColorView& cv : views) {
    const PinholeView& view = cv.view;
    if (cv.image.rows != view.height || cv.image.cols != view.width ||
        (cv.image.type() != CV_32FC3 && cv.image.type() != CV_8UC3))
      throw std::invalid_argument("ColorizeMesh: the image must be CV_32FC3 or CV_8UC3 of the view's size");
    const cv::Mat depth = cv.depth.empty() ? RenderMeshDepth(*mesh, view) : cv.depth;
    if (depth.type() != CV_32F || depth.size() != cv.image.size())
      throw std::invalid_argument("ColorizeMesh: the depth must be CV_32F of the view's size");
    const Eigen::Vector3d center = view.Center();
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n), [&](const auto& range) {
      for (std::size_t i = range.begin(); i < range.end(); ++i) {
        const Eigen::Vector3d x = mesh->vertices[i].cast<double>();
        const Eigen::Vector3d xc = view.R * x + view.t;
        if (xc.z() <= 1e-6) continue;
        const Eigen::Vector3d h = view.K * xc;
        const double u = h.x() / h.z(), v = h.y() / h.z();
        if (!(u >= 0 && v >= 0 && u < view.width && v < view.height)) continue;
        const double cosang = mesh->normals[i].cast<double>().dot((center - x).normalized());
        if (cosang < options.min_cos) continue;
        const float d = depth.at<float>(static_cast<int>(v), static_cast<int>(u));
        if (!(d > 0) || xc.z() > d + options.depth_tolerance) continue;
        Eigen::Vector3d bgr;
        if (!SampleVisibleBgr(cv.image, depth, u, v, xc.z(), options.depth_tolerance, &bgr)) continue;
        sum[i] += cosang * bgr;
        weight[i] += cosang;
      }
    });
  }
  mesh->colors.assign(n, Color3u8(128, 128, 128));
  for (std::size_t i = 0; i < n; ++i) {
    if (weight[i] <= 0) continue;
    const Eigen::Vector3d bgr = (sum[i] / weight[i]).cwiseMax(0.0).cwiseMin(1.0) * 255.0;
    mesh->colors[i] = Color3u8(static_cast<std::uint8_t>(std::lround(bgr[2])),
                               static_cast<std::uint8_t>(std::lround(bgr[1])),
                               static_cast<std::uint8_t>(std::lround(bgr[0])));
  }
}

}  // namespace lfrecon
