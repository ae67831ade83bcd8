#include "export/export.h"

#include <open3d/geometry/TriangleMesh.h>
#include <open3d/io/TriangleMeshIO.h>
#include <spdlog/spdlog.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cctype>
#include <fstream>
#include <memory>
#include <tuple>
#include <unordered_map>

#include "io/colmap_dense.h"
#include "io/colmap_model.h"
#include "io/frame_source.h"
#include "io/ply.h"
#include "util/error.h"
#include "util/path.h"

namespace lfrecon {
namespace fs = std::filesystem;

namespace {

void CreateDirs(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw InputError(dir.string(), "cannot create folder: " + ec.message());
}

}  // namespace

void WriteMeshFile(const TriangleMesh& mesh, const fs::path& path) {
  const std::string ext = LowerExtension(path);
  if (ext == ".ply") {
    WritePly(mesh, path);
    return;
  }
  if (ext != ".obj" && ext != ".glb" && ext != ".gltf")
    throw InputError(path.string(), "unsupported mesh format '" + ext + "' (ply, obj, glb, gltf)");
  open3d::geometry::TriangleMesh o;
  o.vertices_.reserve(mesh.vertices.size());
  for (const auto& v : mesh.vertices) o.vertices_.push_back(v.cast<double>());
  for (const auto& t : mesh.triangles) o.triangles_.push_back(t);
  if (mesh.HasNormals())
    for (const auto& n : mesh.normals) o.vertex_normals_.push_back(n.cast<double>());
  if (mesh.HasColors())
    for (const auto& c : mesh.colors) o.vertex_colors_.push_back(c.cast<double>() / 255.0);
  // Open3D's OBJ writer also writes NAME.mtl beside it; GLB is one binary file.
  if (!open3d::io::WriteTriangleMesh(path.string(), o, /*write_ascii=*/false, /*compressed=*/false,
                                     /*write_vertex_normals=*/mesh.HasNormals(),
                                     /*write_vertex_colors=*/mesh.HasColors(), /*write_triangle_uvs=*/false))
    throw InputError(path.string(), "Open3D could not write the mesh");
}

cv::Mat NormalsFromDepth(const PinholeView& view, const cv::Mat& depth) {
  // Central differences two pixels apart, then the mean over a 5x5 window of the
  // valid normals: single-pixel differences of a noisy map are too noisy for
  // COLMAP's fusion (10 degrees between normals by default).
  constexpr int kGap = 2, kWindow = 2;
  cv::Mat raw(depth.rows, depth.cols, CV_32FC3, cv::Scalar::all(0));
  auto point = [&](int r, int c, Eigen::Vector3d* p) {
    if (r < 0 || c < 0 || r >= depth.rows || c >= depth.cols) return false;
    const float d = depth.at<float>(r, c);
    if (!(d > 0) || !std::isfinite(d)) return false;
    *p = view.K_inv * Eigen::Vector3d(c + 0.5, r + 0.5, 1.0) * d;
    return true;
  };
  for (int r = 0; r < depth.rows; ++r)
    for (int c = 0; c < depth.cols; ++c) {
      Eigen::Vector3d p, l, rr, u, d;
      if (!point(r, c, &p) || !point(r, c - kGap, &l) || !point(r, c + kGap, &rr) || !point(r - kGap, c, &u) ||
          !point(r + kGap, c, &d))
        continue;
      // Not across depth edges: the centre near its neighbours' midpoint (true on slanted planes too).
      if (std::abs(l.z() + rr.z() - 2 * p.z()) > 0.02 * p.z() || std::abs(u.z() + d.z() - 2 * p.z()) > 0.02 * p.z())
        continue;
      Eigen::Vector3d n = (rr - l).cross(d - u);
      if (!(n.norm() > 0)) continue;
      n.normalize();
      if (n.dot(p) > 0) n = -n;  // towards the camera
      raw.at<cv::Vec3f>(r, c) = cv::Vec3f(static_cast<float>(n.x()), static_cast<float>(n.y()), static_cast<float>(n.z()));
    }
  cv::Mat normals(depth.rows, depth.cols, CV_32FC3, cv::Scalar::all(0));
  for (int r = 0; r < depth.rows; ++r)
    for (int c = 0; c < depth.cols; ++c) {
      if (raw.at<cv::Vec3f>(r, c) == cv::Vec3f(0, 0, 0)) continue;
      cv::Vec3f sum(0, 0, 0);
      for (int dr = -kWindow; dr <= kWindow; ++dr)
        for (int dc = -kWindow; dc <= kWindow; ++dc) {
          const int rr = r + dr, cc = c + dc;
          if (rr >= 0 && cc >= 0 && rr < depth.rows && cc < depth.cols) sum += raw.at<cv::Vec3f>(rr, cc);
        }
      const float len = static_cast<float>(cv::norm(sum));
      if (len > 0) normals.at<cv::Vec3f>(r, c) = sum / len;
    }
  return normals;
}

struct PointCloudAccumulator::Impl {
  struct Cell {
    Eigen::Vector3d p = Eigen::Vector3d::Zero(), n = Eigen::Vector3d::Zero(), c = Eigen::Vector3d::Zero();
    std::int64_t count = 0, colored = 0;
  };
  BoundingBox volume;
  double voxel = 0;
  std::unordered_map<std::int64_t, Cell> cells;
  std::vector<Cell> points;  // voxel <= 0
};

PointCloudAccumulator::PointCloudAccumulator(const BoundingBox& volume, double voxel) : impl_(new Impl) {
  impl_->volume = volume;
  impl_->voxel = voxel;
}
PointCloudAccumulator::~PointCloudAccumulator() { delete impl_; }

void PointCloudAccumulator::Add(const PinholeView& v, const cv::Mat& d, const cv::Mat& color) {
  const cv::Mat normals = NormalsFromDepth(v, d);
  const bool colored = !color.empty() && color.size() == d.size();
  const Eigen::Vector3d origin = impl_->volume.min;
  const double voxel = impl_->voxel;
  for (int r = 0; r < d.rows; ++r)
    for (int c = 0; c < d.cols; ++c) {
      const float z = d.at<float>(r, c);
      if (!(z > 0) || !std::isfinite(z)) continue;
      const Eigen::Vector3d p = v.Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), z);
      if (!impl_->volume.Contains(p)) continue;
      const cv::Vec3f nc = normals.at<cv::Vec3f>(r, c);
      Impl::Cell point;
      point.p = p;
      point.n = v.R.transpose() * Eigen::Vector3d(nc[0], nc[1], nc[2]);
      point.count = 1;
      if (colored) {
        cv::Vec3f bgr;
        if (color.depth() == CV_8U) {
          const cv::Vec3b b = color.at<cv::Vec3b>(r, c);
          bgr = cv::Vec3f(b[0], b[1], b[2]) / 255.f;
        } else {
          bgr = color.at<cv::Vec3f>(r, c);
        }
        point.c = Eigen::Vector3d(bgr[2], bgr[1], bgr[0]);
        point.colored = 1;
      }
      if (voxel <= 0) {
        impl_->points.push_back(point);
        continue;
      }
      const Eigen::Vector3d q = (p - origin) / voxel;
      const std::int64_t x = static_cast<std::int64_t>(q.x()), y = static_cast<std::int64_t>(q.y()),
                         zz = static_cast<std::int64_t>(q.z());
      Impl::Cell& cell = impl_->cells[(x << 42) ^ (y << 21) ^ zz];  // V spans < 2^21 voxels a side
      cell.p += point.p;
      cell.n += point.n;
      cell.c += point.c;
      cell.count += 1;
      cell.colored += point.colored;
    }
}

TriangleMesh PointCloudAccumulator::Result() const {
  std::vector<Impl::Cell> cells = impl_->points;
  for (const auto& [key, cell] : impl_->cells) cells.push_back(cell);
  // Deterministic order: by position.
  std::sort(cells.begin(), cells.end(), [](const Impl::Cell& a, const Impl::Cell& b) {
    const Eigen::Vector3d pa = a.p / a.count, pb = b.p / b.count;
    return std::tie(pa.x(), pa.y(), pa.z()) < std::tie(pb.x(), pb.y(), pb.z());
  });
  bool all_colored = !cells.empty();
  for (const auto& cell : cells) all_colored = all_colored && cell.colored == cell.count;
  TriangleMesh out;
  for (const auto& cell : cells) {
    out.vertices.push_back((cell.p / cell.count).cast<float>());
    Eigen::Vector3d n = cell.n;
    if (n.norm() > 0) n.normalize();
    out.normals.push_back(n.cast<float>());
    if (all_colored) {
      const Eigen::Vector3d c = (cell.c / cell.count * 255.0).cwiseMax(0.0).cwiseMin(255.0);
      out.colors.push_back(Color3u8(static_cast<std::uint8_t>(std::lround(c.x())),
                                    static_cast<std::uint8_t>(std::lround(c.y())),
                                    static_cast<std::uint8_t>(std::lround(c.z()))));
    }
  }
  return out;
}

TriangleMesh PointCloudFromDepthMaps(const std::vector<PinholeView>& views, const std::vector<cv::Mat>& depth,
                                     const std::vector<cv::Mat>& colors, const BoundingBox& volume, double voxel) {
  if (views.size() != depth.size()) throw std::invalid_argument("PointCloudFromDepthMaps: one depth map per view");
  PointCloudAccumulator acc(volume, voxel);
  for (size_t k = 0; k < views.size(); ++k) acc.Add(views[k], depth[k], k < colors.size() ? colors[k] : cv::Mat());
  return acc.Result();
}

struct ColmapWorkspaceWriter::Impl {
  fs::path dir;
  std::vector<std::string> names;
  std::vector<PinholeView> views;
  // Sparse points (sampled from the depth maps): COLMAP's fusion only compares
  // images that share sparse points (Model::GetMaxOverlappingImages).
  std::vector<Eigen::Vector3d> points;
  std::vector<cv::Vec3b> point_colors;  // RGB
  bool finished = false;
};

ColmapWorkspaceWriter::ColmapWorkspaceWriter(fs::path dir) : impl_(new Impl) {
  impl_->dir = std::move(dir);
  for (const char* sub : {"images", "sparse", "stereo/depth_maps", "stereo/normal_maps", "stereo/consistency_graphs"})
    CreateDirs(impl_->dir / sub);
}

ColmapWorkspaceWriter::~ColmapWorkspaceWriter() {
  try {
    if (!impl_->finished) Finish();
  } catch (const std::exception& e) {
    spdlog::error("COLMAP workspace {}: {}", impl_->dir.string(), e.what());
  }
  delete impl_;
}

std::string ColmapWorkspaceWriter::Add(const ColmapWorkspaceView& w) {
  const fs::path& dir = impl_->dir;
  std::string name = w.name;
  if (LowerExtension(name) != ".png") name += ".png";
  for (char& ch : name)
    if (ch == '/' || ch == '\\') ch = '_';  // one flat folder
  WriteImageFloat(dir / "images" / name, w.image);
  cv::Mat depth = w.depth.clone();
  cv::patchNaNs(depth, 0);
  cv::max(depth, 0, depth);
  WriteColmapDenseMap(dir / "stereo" / "depth_maps" / (name + ".geometric.bin"), depth);
  WriteColmapDenseMap(dir / "stereo" / "normal_maps" / (name + ".geometric.bin"), NormalsFromDepth(w.view, depth));
  // About 100 sparse points per view, on a regular pixel grid.
  const int valid = cv::countNonZero(depth > 0);
  const int step = std::max(1, static_cast<int>(std::sqrt(std::max(1, valid) / 100.0)));
  cv::Mat image8;
  if (w.image.depth() == CV_8U) image8 = w.image; else w.image.convertTo(image8, CV_8U, 255.0);
  for (int r = step / 2; r < depth.rows; r += step)
    for (int c = step / 2; c < depth.cols; c += step) {
      const float z = depth.at<float>(r, c);
      if (!(z > 0)) continue;
      impl_->points.push_back(w.view.Unproject(Eigen::Vector2d(c + 0.5, r + 0.5), z));
      const cv::Vec3b bgr = image8.at<cv::Vec3b>(r, c);
      impl_->point_colors.emplace_back(bgr[2], bgr[1], bgr[0]);
    }
  impl_->views.push_back(w.view);
  impl_->names.push_back(name);
  return name;
}

void ColmapWorkspaceWriter::Finish() {
  impl_->finished = true;
  const fs::path& dir = impl_->dir;
  const std::size_t n = impl_->views.size();
  // Tracks: a sparse point is observed by every view whose depth map agrees
  // with it (within 1 % of the depth) where it projects.
  std::vector<std::vector<std::pair<std::uint32_t, std::uint32_t>>> tracks(impl_->points.size());
  std::vector<std::vector<std::pair<Eigen::Vector2d, std::int64_t>>> points2d(n);
  for (std::size_t j = 0; j < n; ++j) {
    const cv::Mat depth = ReadColmapDenseMap(dir / "stereo" / "depth_maps" / (impl_->names[j] + ".geometric.bin"));
    const PinholeView& v = impl_->views[j];
    for (std::size_t k = 0; k < impl_->points.size(); ++k) {
      Eigen::Vector2d px;
      const double z = v.Project(impl_->points[k], &px);
      if (z <= 0 || !v.InImage(px)) continue;
      const float d = depth.at<float>(static_cast<int>(px.y()), static_cast<int>(px.x()));
      if (!(d > 0) || std::abs(d - z) > 0.01 * z) continue;
      tracks[k].emplace_back(static_cast<std::uint32_t>(j + 1), static_cast<std::uint32_t>(points2d[j].size()));
      points2d[j].emplace_back(px, static_cast<std::int64_t>(k));
    }
  }
  // Point ids: 1.. over the points seen at least twice; -1 for the others' 2D observations.
  std::vector<std::int64_t> id(impl_->points.size(), -1);
  std::int64_t next = 1;
  for (std::size_t k = 0; k < tracks.size(); ++k)
    if (tracks[k].size() >= 2) id[k] = next++;
  const fs::path sparse = dir / "sparse";
  std::ofstream cams(sparse / "cameras.txt"), imgs(sparse / "images.txt"), pts(sparse / "points3D.txt");
  cams << "# Camera list with one line of data per camera:\n#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n";
  imgs << "# Image list with two lines of data per image:\n#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
          "#   POINTS2D[] as (X, Y, POINT3D_ID)\n";
  pts << "# 3D point list with one line of data per point:\n"
         "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n";
  cams.precision(17);
  imgs.precision(17);
  pts.precision(17);
  for (std::size_t j = 0; j < n; ++j) {
    const PinholeView& v = impl_->views[j];
    cams << j + 1 << " PINHOLE " << v.width << " " << v.height << " " << v.K(0, 0) << " " << v.K(1, 1) << " "
         << v.K(0, 2) << " " << v.K(1, 2) << "\n";
    const Eigen::Quaterniond q = Eigen::Quaterniond(v.R).normalized();
    imgs << j + 1 << " " << q.w() << " " << q.x() << " " << q.y() << " " << q.z() << " " << v.t.x() << " " << v.t.y()
         << " " << v.t.z() << " " << j + 1 << " " << impl_->names[j] << "\n";
    for (std::size_t i = 0; i < points2d[j].size(); ++i)
      imgs << (i ? " " : "") << points2d[j][i].first.x() << " " << points2d[j][i].first.y() << " "
           << id[static_cast<std::size_t>(points2d[j][i].second)];
    imgs << "\n";
  }
  for (std::size_t k = 0; k < tracks.size(); ++k) {
    if (id[k] < 0) continue;
    const Eigen::Vector3d& p = impl_->points[k];
    const cv::Vec3b& c = impl_->point_colors[k];
    pts << id[k] << " " << p.x() << " " << p.y() << " " << p.z() << " " << int(c[0]) << " " << int(c[1]) << " "
        << int(c[2]) << " 0";
    for (const auto& [image, idx] : tracks[k]) pts << " " << image << " " << idx;
    pts << "\n";
  }
  std::ofstream fusion_cfg(dir / "stereo" / "fusion.cfg"), patch_cfg(dir / "stereo" / "patch-match.cfg");
  for (const std::string& name : impl_->names) {
    fusion_cfg << name << "\n";
    patch_cfg << name << "\n__auto__, 20\n";
  }
  cams.close();
  imgs.close();
  pts.close();
  fusion_cfg.close();
  patch_cfg.close();
  if (!cams || !imgs || !pts) throw InputError(sparse.string(), "cannot write the sparse model");
  if (!fusion_cfg || !patch_cfg) throw InputError((dir / "stereo").string(), "cannot write fusion.cfg/patch-match.cfg");
  spdlog::info("{}: {} sparse points seen by at least 2 views", sparse.string(), next - 1);
}

std::vector<std::string> WriteColmapWorkspace(const fs::path& dir, const std::vector<ColmapWorkspaceView>& views) {
  ColmapWorkspaceWriter writer(dir);
  std::vector<std::string> names;
  for (const ColmapWorkspaceView& v : views) names.push_back(writer.Add(v));
  writer.Finish();
  return names;
}

}  // namespace lfrecon
