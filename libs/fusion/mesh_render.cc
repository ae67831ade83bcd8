#include "fusion/mesh_render.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "util/error.h"

namespace lfrecon {

void TurntableOptions::Check() const {
  if (views < 1 || views > 64) throw OptionError("turntable: views must be in [1, 64]");
  if (tile_size < 16 || tile_size > 4096) throw OptionError("turntable: tile_size must be in [16, 4096]");
  if (!(hfov_deg > 1 && hfov_deg < 170)) throw OptionError("turntable: hfov_deg must be in (1, 170)");
  if (!(std::abs(elevation_deg) < 89)) throw OptionError("turntable: |elevation_deg| must be < 89");
}

cv::Mat RenderShaded(const TriangleMesh& mesh, const PinholeView& view) {
  const int W = view.width, H = view.height;
  cv::Mat zbuf(H, W, CV_32F, cv::Scalar(std::numeric_limits<float>::infinity()));
  cv::Mat tri_id(H, W, CV_32S, cv::Scalar(-1));
  std::vector<Eigen::Vector3d> cam(mesh.vertices.size());
  for (std::size_t i = 0; i < mesh.vertices.size(); ++i) cam[i] = view.R * mesh.vertices[i].cast<double>() + view.t;
  // Z-buffer of triangle ids (serial: triangles overlap in the buffer).
  for (std::size_t ti = 0; ti < mesh.triangles.size(); ++ti) {
    const Eigen::Vector3i& t = mesh.triangles[ti];
    Eigen::Vector3d z, u, v;
    bool ok = true;
    for (int k = 0; k < 3 && ok; ++k) {
      const Eigen::Vector3d& x = cam[t[k]];
      ok = x.z() > 1e-6;
      const Eigen::Vector3d h = view.K * x;
      z[k] = x.z();
      u[k] = h.x() / h.z();
      v[k] = h.y() / h.z();
    }
    if (!ok) continue;
    const double area = (u[1] - u[0]) * (v[2] - v[0]) - (u[2] - u[0]) * (v[1] - v[0]);
    if (std::abs(area) < 1e-12) continue;
    const int c0 = std::max(0, static_cast<int>(std::ceil(u.minCoeff() - 0.5)));
    const int c1 = std::min(W - 1, static_cast<int>(std::floor(u.maxCoeff() - 0.5)));
    const int r0 = std::max(0, static_cast<int>(std::ceil(v.minCoeff() - 0.5)));
    const int r1 = std::min(H - 1, static_cast<int>(std::floor(v.maxCoeff() - 0.5)));
    for (int r = r0; r <= r1; ++r) {
      const double py = r + 0.5;
      float* zr = zbuf.ptr<float>(r);
      int* ir = tri_id.ptr<int>(r);
      for (int c = c0; c <= c1; ++c) {
        const double px = c + 0.5;
        const double b0 = ((u[1] - px) * (v[2] - py) - (u[2] - px) * (v[1] - py)) / area;
        const double b1 = ((u[2] - px) * (v[0] - py) - (u[0] - px) * (v[2] - py)) / area;
        const double b2 = 1 - b0 - b1;
        if (b0 < 0 || b1 < 0 || b2 < 0) continue;
        const float zz = static_cast<float>(1.0 / (b0 / z[0] + b1 / z[1] + b2 / z[2]));
        if (zz < zr[c]) {
          zr[c] = zz;
          ir[c] = static_cast<int>(ti);
        }
      }
    }
  }
  // Shade: flat face normal against the viewing ray (two-sided, so inverted
  // or open surfaces still show), times the interpolated vertex colour.
  cv::Mat out(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  const bool colors = mesh.HasColors();
  tbb::parallel_for(0, H, [&](int r) {
    const int* ir = tri_id.ptr<int>(r);
    cv::Vec3b* o = out.ptr<cv::Vec3b>(r);
    for (int c = 0; c < W; ++c) {
      if (ir[c] < 0) continue;
      const Eigen::Vector3i& t = mesh.triangles[ir[c]];
      const Eigen::Vector3d a = mesh.vertices[t[0]].cast<double>(), b = mesh.vertices[t[1]].cast<double>(),
                            d = mesh.vertices[t[2]].cast<double>();
      const Eigen::Vector3d n = (b - a).cross(d - a).normalized();
      const Eigen::Vector3d ray = view.RayDirection({c + 0.5, r + 0.5});
      const double shade = 0.25 + 0.75 * std::abs(n.dot(ray));
      Eigen::Vector3d rgb(0.75, 0.75, 0.75);
      if (colors) {
        rgb.setZero();
        for (int k = 0; k < 3; ++k) rgb += mesh.colors[t[k]].cast<double>() / (3 * 255.0);
      }
      const Eigen::Vector3d s = (shade * rgb * 255.0).cwiseMin(255.0);
      o[c] = cv::Vec3b(static_cast<uchar>(s.z()), static_cast<uchar>(s.y()), static_cast<uchar>(s.x()));
    }
  });
  return out;
}

cv::Mat RenderTurntable(const TriangleMesh& mesh, const BoundingBox& volume, const TurntableOptions& options) {
  options.Check();
  const int S = options.tile_size;
  cv::Mat strip(S, S * options.views, CV_8UC3, cv::Scalar(255, 255, 255));
  const Eigen::Vector3d target = 0.5 * (volume.min + volume.max);
  const double radius = 0.5 * volume.Extent().norm();
  const double half = 0.5 * options.hfov_deg * M_PI / 180.0;
  const double dist = radius / std::sin(half) * 1.05;
  const double f = 0.5 * S / std::tan(half);
  const double el = options.elevation_deg * M_PI / 180.0;
  for (int k = 0; k < options.views; ++k) {
    const double az = 2 * M_PI * k / options.views;
    const Eigen::Vector3d eye =
        target + dist * Eigen::Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
    const Rigid3d pose = LookAt(eye, target, Eigen::Vector3d::UnitZ());
    PinholeView view;
    view.width = view.height = S;
    view.K << f, 0, 0.5 * S, 0, f, 0.5 * S, 0, 0, 1;
    view.K_inv = view.K.inverse();
    view.R = pose.rotation.toRotationMatrix();
    view.t = pose.translation;
    RenderShaded(mesh, view).copyTo(strip(cv::Rect(k * S, 0, S, S)));
  }
  return strip;
}

}  // namespace lfrecon
