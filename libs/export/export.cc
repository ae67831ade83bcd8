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

namespace lfrecon {
namespace fs = std::filesystem;

namespace {

std::string LowerExtension(const fs::path& p) {
  std::string e = p.extension().string();
  std::transform(e.begin(), e.end(), e.begin(), [](unsigned char c) { return std::tolower(c); });
  return e;
}

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
  cv::Mat normals(depth.rows, depth.cols, CV_32FC3, cv::Scalar::all(0));
  auto point = [&](int r, int c, Eigen::Vector3d* p) {
    const float d = depth.at<float>(r, c);
    if (!(d > 0) || !std::isfinite(d)) return false;
    *p = view.K_inv * Eigen::Vector3d(c + 0.5, r + 0.5, 1.0) * d;
    return true;
  };
  for (int r = 1; r + 1 < depth.rows; ++r)
    for (int c = 1; c + 1 < depth.cols; ++c) {
      Eigen::Vector3d p, l, rr, u, d;
      if (!point(r, c, &p) || !point(r, c - 1, &l) || !point(r, c + 1, &rr) || !point(r - 1, c, &u) ||
          !point(r + 1, c, &d))
        continue;
      Eigen::Vector3d n = (rr - l).cross(d - u);
      if (!(n.norm() > 0)) continue;
      n.normalize();
      if (n.dot(p) > 0) n = -n;  // towards the camera
      normals.at<cv::Vec3f>(r, c) = cv::Vec3f(static_cast<float>(n.x()), static_cast<float>(n.y()),
                                              static_cast<float>(n.z()));
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
  ColmapModel model;
  std::vector<std::string> names;
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
  const std::uint32_t id = static_cast<std::uint32_t>(impl_->names.size() + 1);
  impl_->model.cameras[id] =
      Camera::Pinhole(w.view.width, w.view.height, w.view.K(0, 0), w.view.K(1, 1), w.view.K(0, 2), w.view.K(1, 2));
  ColmapImage image;
  image.image_id = id;
  image.camera_id = id;
  image.name = name;
  image.cam_from_world = Rigid3d(Eigen::Quaterniond(w.view.R).normalized(), w.view.t);
  impl_->model.images.push_back(image);
  impl_->names.push_back(name);
  return name;
}

void ColmapWorkspaceWriter::Finish() {
  impl_->finished = true;
  const fs::path& dir = impl_->dir;
  WriteColmapModelText(impl_->model, dir / "sparse");
  std::ofstream fusion_cfg(dir / "stereo" / "fusion.cfg"), patch_cfg(dir / "stereo" / "patch-match.cfg");
  for (const std::string& name : impl_->names) {
    fusion_cfg << name << "\n";
    patch_cfg << name << "\n__auto__, 20\n";
  }
  fusion_cfg.close();
  patch_cfg.close();
  if (!fusion_cfg || !patch_cfg) throw InputError((dir / "stereo").string(), "cannot write fusion.cfg/patch-match.cfg");
}

std::vector<std::string> WriteColmapWorkspace(const fs::path& dir, const std::vector<ColmapWorkspaceView>& views) {
  ColmapWorkspaceWriter writer(dir);
  std::vector<std::string> names;
  for (const ColmapWorkspaceView& v : views) names.push_back(writer.Add(v));
  writer.Finish();
  return names;
}

}  // namespace lfrecon
