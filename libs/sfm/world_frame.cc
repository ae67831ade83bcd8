#include "sfm/world_frame.h"

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <sstream>

#include "util/error.h"

namespace lfrecon {
namespace fs = std::filesystem;

namespace {

constexpr double kRadToDeg = 180.0 / M_PI;

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  const std::size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + mid, v.end());
  return v[mid];
}

double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  const std::size_t k = std::min(v.size() - 1, static_cast<std::size_t>(std::lround(q * (v.size() - 1))));
  std::nth_element(v.begin(), v.begin() + k, v.end());
  return v[k];
}

template <typename T>
void ReadRaw(std::ifstream& in, T* value, const fs::path& path, const std::string& field) {
  in.read(reinterpret_cast<char*>(value), sizeof(T));
  if (!in) throw InputError(path.string(), field, "file ends early");
}

std::vector<SparsePoint> ReadBinary(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path.string(), "cannot open");
  in.seekg(0, std::ios::end);
  const auto size = static_cast<std::uint64_t>(in.tellg());
  in.seekg(0);
  std::uint64_t n = 0;
  ReadRaw(in, &n, path, "num_points3D");
  constexpr std::uint64_t kMinPointBytes = 8 + 24 + 3 + 8 + 8;
  if (n > size / kMinPointBytes) throw InputError(path.string(), "num_points3D", "larger than the file can hold");
  std::vector<SparsePoint> points(n);
  for (std::uint64_t i = 0; i < n; ++i) {
    const std::string field = "point " + std::to_string(i);
    std::uint64_t id = 0, track = 0;
    double xyz[3];
    std::uint8_t rgb[3];
    ReadRaw(in, &id, path, field);
    for (double& c : xyz) ReadRaw(in, &c, path, field);
    for (std::uint8_t& c : rgb) ReadRaw(in, &c, path, field);
    ReadRaw(in, &points[i].error, path, field);
    ReadRaw(in, &track, path, field);
    const std::uint64_t here = static_cast<std::uint64_t>(in.tellg());
    if (track > (size - here) / 8) throw InputError(path.string(), field + " track length", "larger than the file");
    points[i].xyz = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]);
    points[i].image_ids.resize(track);
    for (std::uint64_t k = 0; k < track; ++k) {
      std::uint32_t image_id = 0, point2d = 0;
      ReadRaw(in, &image_id, path, field);
      ReadRaw(in, &point2d, path, field);
      points[i].image_ids[k] = image_id;
    }
    if (!points[i].xyz.allFinite()) throw InputError(path.string(), field, "non-finite coordinates");
  }
  return points;
}

std::vector<SparsePoint> ReadText(const fs::path& path) {
  std::ifstream in(path);
  if (!in) throw InputError(path.string(), "cannot open");
  std::vector<SparsePoint> points;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.empty() || line[0] == '#') continue;
    std::istringstream s(line);
    SparsePoint p;
    std::uint64_t id;
    int r, g, b;
    if (!(s >> id >> p.xyz.x() >> p.xyz.y() >> p.xyz.z() >> r >> g >> b >> p.error) || !p.xyz.allFinite())
      throw InputError(path.string(), "line " + std::to_string(line_no), "expected POINT3D_ID X Y Z R G B ERROR");
    std::uint32_t image_id, idx;
    while (s >> image_id >> idx) p.image_ids.push_back(image_id);
    points.push_back(std::move(p));
  }
  return points;
}

}  // namespace

Rigid3d Similarity3d::TransformPose(const Rigid3d& cam_from_world) const {
  const Eigen::Matrix3d Rc = cam_from_world.rotation.toRotationMatrix() * rotation.transpose();
  const Eigen::Vector3d tc = scale * cam_from_world.translation - Rc * translation;
  return Rigid3d(Eigen::Quaterniond(Rc).normalized(), tc);
}

Similarity3d Similarity3d::Inverse() const {
  Similarity3d inv;
  inv.scale = 1.0 / scale;
  inv.rotation = rotation.transpose();
  inv.translation = -inv.scale * (inv.rotation * translation);
  return inv;
}

std::vector<SparsePoint> ReadColmapPoints3D(const fs::path& model_dir) {
  if (fs::is_regular_file(model_dir / "points3D.bin")) return ReadBinary(model_dir / "points3D.bin");
  if (fs::is_regular_file(model_dir / "points3D.txt")) return ReadText(model_dir / "points3D.txt");
  throw InputError((model_dir / "points3D.bin").string(), "missing (nor points3D.txt)");
}

void WorldFrameOptions::Check() const {
  LFRECON_CHECK_OPTION(camera_distance > 0 && std::isfinite(camera_distance));
  LFRECON_CHECK_OPTION(min_track_length >= 2);
  LFRECON_CHECK_OPTION(max_error_px > 0);
  LFRECON_CHECK_OPTION(central_fraction > 0 && central_fraction <= 1);
  LFRECON_CHECK_OPTION(min_view_fraction > 0 && min_view_fraction <= 1);
  LFRECON_CHECK_OPTION(percentile >= 0 && percentile < 0.5);
  LFRECON_CHECK_OPTION(padding >= 0);
  LFRECON_CHECK_OPTION(max_views >= 1);
  LFRECON_CHECK_OPTION(planar_min_spread >= 0 && planar_max_thickness >= 0);
  LFRECON_CHECK_OPTION(planar_max_tilt_deg >= 0 && planar_max_tilt_deg <= 90);
}

WorldFrame EstimateWorldFrame(const std::vector<Rigid3d>& cam_from_world, const std::vector<Camera>& cameras,
                              const std::vector<SparsePoint>& points, const WorldFrameOptions& options,
                              const std::string& source) {
  options.Check();
  if (cam_from_world.size() != cameras.size())
    throw std::invalid_argument("EstimateWorldFrame: one camera per view expected");
  if (cam_from_world.size() < 2) throw InputError(source, "fewer than 2 registered views");
  WorldFrame frame;

  // Up: the mean of the cameras' up vectors (-y of the OpenCV camera frame).
  Eigen::Vector3d up = Eigen::Vector3d::Zero();
  for (const Rigid3d& p : cam_from_world) up += p.rotation.inverse() * Eigen::Vector3d(0, -1, 0);
  if (up.norm() < 1e-9) throw InputError(source, "the cameras' up vectors cancel out; no up axis");
  up.normalize();
  // A planar camera path that spans two directions (a ring or an arc around the
  // object, as captures are): its normal is the up axis, on the side of the
  // mean up. The mean up alone tilts towards the object on an arc (the cameras
  // look down at it), by up to the pitch.
  {
    Eigen::Vector3d mean = Eigen::Vector3d::Zero();
    for (const Rigid3d& p : cam_from_world) mean += CameraCenter(p);
    mean /= static_cast<double>(cam_from_world.size());
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    for (const Rigid3d& p : cam_from_world) {
      const Eigen::Vector3d d = CameraCenter(p) - mean;
      cov += d * d.transpose();
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(cov);  // ascending eigenvalues
    const Eigen::Vector3d ev = eig.eigenvalues();
    const Eigen::Vector3d normal = eig.eigenvectors().col(0);
    const bool planar = ev(1) > options.planar_min_spread * ev(2) && ev(0) < options.planar_max_thickness * ev(1);
    if (planar && std::abs(normal.dot(up)) > std::cos(options.planar_max_tilt_deg / kRadToDeg)) {
      frame.up_from_path = true;
      up = normal.dot(up) > 0 ? normal : Eigen::Vector3d(-normal);
    }
  }
  double spread = 0;
  for (const Rigid3d& p : cam_from_world)
    spread += std::acos(std::clamp(up.dot(p.rotation.inverse() * Eigen::Vector3d(0, -1, 0)), -1.0, 1.0));
  frame.up_sfm = up;
  frame.up_spread_deg = kRadToDeg * spread / cam_from_world.size();
  const Eigen::Matrix3d R_up = Eigen::Quaterniond::FromTwoVectors(up, Eigen::Vector3d::UnitZ()).toRotationMatrix();

  // The views used for the "looked at" test, evenly spread.
  std::vector<int> views;
  const int n = static_cast<int>(cam_from_world.size());
  const int step = std::max(1, (n + options.max_views - 1) / options.max_views);
  for (int i = 0; i < n; i += step) views.push_back(i);

  // Points the cameras look at: project into the central part of most views.
  std::vector<Eigen::Vector3d> kept;
  std::vector<std::pair<double, Eigen::Vector3d>> scored;  // fallback: the best-looked-at points
  for (const SparsePoint& p : points) {
    if (static_cast<int>(p.image_ids.size()) < options.min_track_length || p.error > options.max_error_px) continue;
    ++frame.points_total;
    int central = 0;
    for (int i : views) {
      const Camera& cam = cameras[i];
      Eigen::Vector2d px;
      if (!cam.Project(cam_from_world[i] * p.xyz, &px)) continue;
      const double hx = 0.5 * options.central_fraction * cam.width, hy = 0.5 * options.central_fraction * cam.height;
      if (std::abs(px.x() - 0.5 * cam.width) <= hx && std::abs(px.y() - 0.5 * cam.height) <= hy) ++central;
    }
    const double fraction = static_cast<double>(central) / views.size();
    if (fraction >= options.min_view_fraction) kept.push_back(p.xyz);
    scored.emplace_back(fraction, p.xyz);
  }
  constexpr std::size_t kMinPoints = 20;
  if (scored.size() < kMinPoints)
    throw InputError(source, "only " + std::to_string(scored.size()) + " sparse points with a track of >= " +
                                 std::to_string(options.min_track_length) + " images; cannot estimate V");
  if (kept.size() < kMinPoints) {
    // Nothing is central in most views (a walk-through rather than an object
    // capture): the best-looked-at fifth of the points.
    std::sort(scored.begin(), scored.end(), [](const auto& a, const auto& b) { return a.first > b.first; });
    kept.clear();
    const std::size_t take = std::max(kMinPoints, scored.size() / 5);
    for (std::size_t i = 0; i < take; ++i) kept.push_back(scored[i].second);
  }
  frame.points_in_volume = static_cast<int>(kept.size());

  // Robust extent in the up-aligned frame.
  BoundingBox box;
  for (int axis = 0; axis < 3; ++axis) {
    std::vector<double> c;
    c.reserve(kept.size());
    for (const Eigen::Vector3d& p : kept) c.push_back((R_up * p)[axis]);
    box.min[axis] = Quantile(c, options.percentile);
    box.max[axis] = Quantile(c, 1.0 - options.percentile);
  }
  const Eigen::Vector3d extent = (box.max - box.min).cwiseMax(1e-9 * (box.max - box.min).norm() + 1e-12);
  box.min -= options.padding * extent;
  box.max += options.padding * extent;
  // The top (not padded): thin and tall things on V's footprint (sticks, legs) have few
  // sparse points and reach beyond the images' central part, so the points'
  // top cuts them. V reaches up to where the views' upper image edge meets the
  // vertical axis through V's centre (the median over the views): what stands
  // there fills the frames up to their top edge.
  {
    std::vector<double> top;
    const Eigen::Vector2d axis(box.Center().x(), box.Center().y());
    for (int i : views) {
      const Camera& cam = cameras[i];
      const Eigen::Vector3d ray_cam = cam.Unproject(Eigen::Vector2d(cam.cx(), 0.0), 1.0);
      const Eigen::Vector3d d = R_up * (cam_from_world[i].rotation.inverse() * ray_cam);
      const Eigen::Vector3d c = R_up * CameraCenter(cam_from_world[i]);
      const double dd = d.head<2>().squaredNorm();
      if (dd < 1e-12) continue;
      const double t = -(c.head<2>() - axis).dot(d.head<2>()) / dd;
      if (t > 0) top.push_back(c.z() + t * d.z());
    }
    if (!top.empty()) {
      const double z = Median(top);
      if (z > box.max.z() && z - box.min.z() < 2 * (box.max - box.min).head<2>().maxCoeff()) box.max.z() = z;
    }
  }

  // Scale: the median camera distance from V's centre becomes camera_distance.
  std::vector<double> dist;
  for (const Rigid3d& p : cam_from_world) dist.push_back((R_up * CameraCenter(p) - box.Center()).norm());
  const double median_dist = Median(dist);
  if (!(median_dist > 0)) throw InputError(source, "cameras coincide with V's centre; no scale");
  const double s = options.camera_distance / median_dist;
  const Eigen::Vector3d origin(box.Center().x(), box.Center().y(), box.min.z());

  frame.sfm_to_world.scale = s;
  frame.sfm_to_world.rotation = R_up;
  frame.sfm_to_world.translation = -s * origin;
  frame.volume.min = s * (box.min - origin);
  frame.volume.max = s * (box.max - origin);
  return frame;
}

Similarity3d AlignCameras(const std::vector<Rigid3d>& estimated, const std::vector<Rigid3d>& reference) {
  if (estimated.size() != reference.size() || estimated.size() < 3)
    throw std::invalid_argument("AlignCameras: needs >= 3 corresponding views");
  Eigen::Matrix3Xd src(3, estimated.size()), dst(3, reference.size());
  for (std::size_t i = 0; i < estimated.size(); ++i) {
    src.col(i) = CameraCenter(estimated[i]);
    dst.col(i) = CameraCenter(reference[i]);
  }
  const Eigen::Matrix4d T = Eigen::umeyama(src, dst, true);
  Similarity3d S;
  const Eigen::Matrix3d sR = T.topLeftCorner<3, 3>();
  S.scale = std::cbrt(sR.determinant());
  S.rotation = sR / S.scale;
  S.translation = T.topRightCorner<3, 1>();
  return S;
}

PoseErrors ComparePoses(const std::vector<Rigid3d>& estimated, const std::vector<Rigid3d>& reference,
                        const Similarity3d& estimated_to_reference, const Eigen::Vector3d& reference_point) {
  if (estimated.size() != reference.size()) throw std::invalid_argument("ComparePoses: sizes differ");
  PoseErrors e;
  e.views = static_cast<int>(estimated.size());
  std::vector<double> rot, center, dist;
  for (std::size_t i = 0; i < estimated.size(); ++i) {
    const Rigid3d mapped = estimated_to_reference.TransformPose(estimated[i]);
    const Eigen::AngleAxisd d(reference[i].rotation * mapped.rotation.inverse());
    rot.push_back(kRadToDeg * std::abs(d.angle()));
    center.push_back((CameraCenter(mapped) - CameraCenter(reference[i])).norm());
    dist.push_back((CameraCenter(reference[i]) - reference_point).norm());
  }
  if (!rot.empty()) {
    e.median_rotation_deg = Median(rot);
    e.max_rotation_deg = *std::max_element(rot.begin(), rot.end());
    e.median_center = Median(center);
    e.max_center = *std::max_element(center.begin(), center.end());
    e.camera_distance = Median(dist);
  }
  return e;
}

}  // namespace lfrecon
