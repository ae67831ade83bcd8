#include "io/transforms_json.h"

#include <spdlog/spdlog.h>

#include <Eigen/SVD>
#include <cmath>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>

#include "io/input_text.h"
#include "io/json_file.h"
#include "util/error.h"

namespace lfrecon {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// Intrinsics keys may sit at the top level (shared) or in a frame (overrides).
struct IntrinsicsKeys {
  const json* frame;
  const json* top;
  std::string file;
  std::string field;

  const json* Find(const char* key) const {
    if (frame && frame->contains(key)) return &(*frame)[key];
    if (top->contains(key)) return &(*top)[key];
    return nullptr;
  }
  std::optional<double> Number(const char* key) const {
    const json* v = Find(key);
    if (!v || v->is_null()) return std::nullopt;
    if (!v->is_number()) throw InputError(file, field + key, std::string("must be a number, got a ") + v->type_name());
    const double d = v->get<double>();
    if (!std::isfinite(d)) throw InputError(file, field + key, "is not finite");
    return d;
  }
  double Required(const char* key) const {
    const auto v = Number(key);
    if (!v) throw InputError(file, field + key, "missing (needed at the top level or in the frame)");
    return *v;
  }
};

Camera ParseCamera(const IntrinsicsKeys& keys, const std::optional<std::pair<int, int>>& image_size) {
  double w, h;
  if (!keys.Number("w") && !keys.Number("h") && image_size) {
    w = image_size->first;
    h = image_size->second;
  } else {
    w = keys.Required("w");
    h = keys.Required("h");
  }
  if (w < 1 || h < 1 || w != std::floor(w) || h != std::floor(h) || w > 1e6 || h > 1e6)
    throw InputError(keys.file, keys.field + "w/h", "image size must be positive integers");
  double fx, fy;
  if (auto v = keys.Number("fl_x")) {
    fx = *v;
  } else if (auto a = keys.Number("camera_angle_x")) {
    fx = 0.5 * w / std::tan(0.5 * *a);
  } else {
    throw InputError(keys.file, keys.field + "fl_x", "missing focal length (fl_x or camera_angle_x)");
  }
  if (auto v = keys.Number("fl_y")) {
    fy = *v;
  } else if (auto a = keys.Number("camera_angle_y")) {
    fy = 0.5 * h / std::tan(0.5 * *a);
  } else {
    fy = fx;
  }
  const double cx = keys.Number("cx").value_or(0.5 * w);
  const double cy = keys.Number("cy").value_or(0.5 * h);
  bool fisheye = false;
  if (const json* m = keys.Find("camera_model")) {
    if (!m->is_string())
      throw InputError(keys.file, keys.field + "camera_model", std::string("must be a string, got a ") + m->type_name());
    const std::string name = m->get<std::string>();
    if (name != "OPENCV" && name != "PINHOLE" && name != "SIMPLE_PINHOLE" && name != "OPENCV_FISHEYE")
      throw InputError(keys.file, keys.field + "camera_model",
                       "unsupported camera model " + InputToken(name) + " (supported: PINHOLE, OPENCV, OPENCV_FISHEYE)");
    fisheye = name == "OPENCV_FISHEYE";
  }
  const double k1 = keys.Number("k1").value_or(0), k2 = keys.Number("k2").value_or(0);
  const double p1 = keys.Number("p1").value_or(0), p2 = keys.Number("p2").value_or(0);
  const double k3 = keys.Number("k3").value_or(0), k4 = keys.Number("k4").value_or(0);
  Camera camera;
  if (fisheye) {
    camera.model = CameraModelId::kOpenCVFisheye;
    camera.params = {fx, fy, cx, cy, k1, k2, k3, k4};
  } else if (k3 != 0) {
    camera.model = CameraModelId::kFullOpenCV;
    camera.params = {fx, fy, cx, cy, k1, k2, p1, p2, k3, 0, 0, 0};
  } else if (k1 != 0 || k2 != 0 || p1 != 0 || p2 != 0) {
    camera.model = CameraModelId::kOpenCV;
    camera.params = {fx, fy, cx, cy, k1, k2, p1, p2};
  } else {
    camera.model = CameraModelId::kPinhole;
    camera.params = {fx, fy, cx, cy};
  }
  camera.width = static_cast<int>(w);
  camera.height = static_cast<int>(h);
  const std::string problem = camera.Validate();
  if (!problem.empty()) throw InputError(keys.file, keys.field + "intrinsics", problem);
  return camera;
}

// OpenGL camera axes (x right, y up, z backward) -> OpenCV (x right, y down, z forward).
Rigid3d ParsePose(const json& frame, const std::string& file, const std::string& field) {
  if (!frame.contains("transform_matrix")) throw InputError(file, field + "transform_matrix", "missing");
  const json& m = frame["transform_matrix"];
  if (!m.is_array() || (m.size() != 4 && m.size() != 3))
    throw InputError(file, field + "transform_matrix", "must be a 4x4 (or 3x4) array of numbers");
  Eigen::Matrix4d c2w = Eigen::Matrix4d::Identity();
  for (size_t r = 0; r < m.size(); ++r) {
    if (!m[r].is_array() || m[r].size() != 4)
      throw InputError(file, field + "transform_matrix", "row " + std::to_string(r) + " must hold 4 numbers");
    for (int c = 0; c < 4; ++c) {
      if (!m[r][c].is_number())
        throw InputError(file, field + "transform_matrix",
                         "row " + std::to_string(r) + " holds a non-number (a " + m[r][c].type_name() + ")");
      c2w(r, c) = m[r][c].get<double>();
    }
  }
  if (!c2w.allFinite()) throw InputError(file, field + "transform_matrix", "is not finite");
  Eigen::Matrix3d R = c2w.topLeftCorner<3, 3>();
  // float32 files are orthonormal to ~1e-7; a larger error means a scaled or sheared matrix.
  const double ortho_error = (R.transpose() * R - Eigen::Matrix3d::Identity()).norm();
  if (ortho_error > 1e-3 || R.determinant() < 0)
    throw InputError(file, field + "transform_matrix",
                     "rotation part is not a rotation (|R^T R - I| = " + std::to_string(ortho_error) + ")");
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
  R = svd.matrixU() * svd.matrixV().transpose();
  R.col(1) *= -1;  // c2w_cv = c2w_gl * diag(1, -1, -1, 1)
  R.col(2) *= -1;
  Eigen::Quaterniond q(R);
  q.normalize();
  const Rigid3d world_from_cam(q, c2w.block<3, 1>(0, 3));
  return world_from_cam.Inverse();
}

void PutIntrinsics(const Camera& camera, json* out) {
  json& j = *out;
  j["w"] = camera.width;
  j["h"] = camera.height;
  j["fl_x"] = camera.fx();
  j["fl_y"] = camera.fy();
  j["cx"] = camera.cx();
  j["cy"] = camera.cy();
  j["camera_angle_x"] = 2.0 * std::atan(0.5 * camera.width / camera.fx());
  j["camera_angle_y"] = 2.0 * std::atan(0.5 * camera.height / camera.fy());
  const std::vector<double>& p = camera.params;
  switch (camera.model) {
    case CameraModelId::kSimplePinhole:
    case CameraModelId::kPinhole: break;
    case CameraModelId::kSimpleRadial: j["k1"] = p[3]; break;
    case CameraModelId::kRadial:
      j["k1"] = p[3];
      j["k2"] = p[4];
      break;
    case CameraModelId::kFullOpenCV:
      if (p[9] != 0 || p[10] != 0 || p[11] != 0)
        throw std::invalid_argument("transforms.json cannot hold FULL_OPENCV's k4..k6");
      j["k3"] = p[8];
      [[fallthrough]];
    case CameraModelId::kOpenCV:
      j["k1"] = p[4];
      j["k2"] = p[5];
      j["p1"] = p[6];
      j["p2"] = p[7];
      break;
    case CameraModelId::kOpenCVFisheye:
      j["k1"] = p[4];
      j["k2"] = p[5];
      j["k3"] = p[6];
      j["k4"] = p[7];
      j["camera_model"] = "OPENCV_FISHEYE";
      return;
    default:
      throw std::invalid_argument("transforms.json cannot hold a " + CameraModelName(camera.model) + " camera");
  }
  if (camera.HasDistortion()) j["camera_model"] = "OPENCV";
}

}  // namespace

std::vector<TransformsFrame> ReadTransformsJson(const fs::path& path, const TransformsImageSize& image_size) {
  const std::string file = path.string();
  const json root = ReadJsonFile(path);  // depth-limited: no recursion on untrusted nesting
  if (!root.is_object() || !root.contains("frames") || !root["frames"].is_array())
    throw InputError(file, "frames", "missing or not an array");
  std::vector<TransformsFrame> frames;
  const json& list = root["frames"];
  frames.reserve(list.size());
  for (size_t i = 0; i < list.size(); ++i) {
    const json& f = list[i];
    std::string field = "frames[" + std::to_string(i) + "]";
    if (!f.is_object()) throw InputError(file, field, "must be an object");
    if (!f.contains("file_path") || !f["file_path"].is_string() || f["file_path"].get<std::string>().empty())
      throw InputError(file, field + ".file_path", "missing or not a string");
    TransformsFrame frame;
    frame.file_path = f["file_path"].get<std::string>();
    field += " (" + InputToken(frame.file_path) + ").";
    if (f.contains("mask_path")) {
      if (!f["mask_path"].is_string()) throw InputError(file, field + "mask_path", "must be a string");
      frame.mask_path = f["mask_path"].get<std::string>();
    }
    const IntrinsicsKeys keys{&f, &root, file, field};
    std::optional<std::pair<int, int>> size;
    if (!keys.Number("w") && !keys.Number("h") && image_size) size = image_size(frame.file_path);
    frame.camera = ParseCamera(keys, size);
    frame.cam_from_world = ParsePose(f, file, field);
    frames.push_back(std::move(frame));
  }
  spdlog::debug("{}: {} frames", file, frames.size());
  return frames;
}

void WriteTransformsJson(const std::vector<TransformsFrame>& frames, const fs::path& path) {
  bool shared = !frames.empty();
  for (const TransformsFrame& f : frames) shared = shared && f.camera == frames.front().camera;
  json root = json::object();
  if (shared) PutIntrinsics(frames.front().camera, &root);
  json list = json::array();
  for (const TransformsFrame& f : frames) {
    json j = json::object();
    j["file_path"] = f.file_path;
    if (!shared) PutIntrinsics(f.camera, &j);
    const Rigid3d world_from_cam = f.cam_from_world.Inverse();
    Eigen::Matrix4d c2w = Eigen::Matrix4d::Identity();
    c2w.topLeftCorner<3, 4>() = world_from_cam.ToMatrix();
    c2w.col(1) *= -1;  // back to OpenGL axes
    c2w.col(2) *= -1;
    json m = json::array();
    for (int r = 0; r < 4; ++r) m.push_back({c2w(r, 0), c2w(r, 1), c2w(r, 2), c2w(r, 3)});
    j["transform_matrix"] = m;
    list.push_back(std::move(j));
  }
  root["frames"] = std::move(list);
  std::ofstream out(path, std::ios::trunc);
  if (!out) throw InputError(path.string(), "cannot open file for writing");
  out << root.dump(1) << "\n";
  out.close();
  if (!out) throw InputError(path.string(), "write failed");
}

}  // namespace lfrecon
