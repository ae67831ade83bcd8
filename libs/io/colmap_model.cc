#include "io/colmap_model.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <limits>
#include <set>
#include <sstream>
#include <stdexcept>

#include "io/input_text.h"
#include "util/error.h"

namespace lfrecon {
namespace fs = std::filesystem;

namespace {

// ---------------------------------------------------------------------------
// Shared validation

std::string ImageLabel(std::uint32_t id, const std::string& name) {
  return "image " + std::to_string(id) + (name.empty() ? std::string() : " (" + InputToken(name) + ")");
}

// COLMAP normalises quaternions on read; a zero or non-finite one cannot be.
Rigid3d MakePose(const std::string& file, const std::string& field, std::uint32_t image_id,
                 const std::string& name, double qw, double qx, double qy, double qz, double tx, double ty,
                 double tz) {
  Eigen::Quaterniond q(qw, qx, qy, qz);
  const Eigen::Vector3d t(tx, ty, tz);
  if (!q.coeffs().allFinite())
    throw InputError(file, field, ImageLabel(image_id, name) + ": quaternion is not finite");
  const double norm = q.norm();
  if (!(norm > 1e-12))
    throw InputError(file, field,
                     ImageLabel(image_id, name) + ": quaternion has zero length and cannot be normalised");
  if (!t.allFinite())
    throw InputError(file, field, ImageLabel(image_id, name) + ": translation is not finite");
  // Unit to rounding already: keep the stored bits, so binary round trips are exact.
  if (std::abs(norm - 1.0) > 1e-15) q.coeffs() /= norm;
  return Rigid3d(q, t);
}

void CheckCamera(const std::string& file, const std::string& field, std::uint32_t camera_id,
                 const Camera& camera) {
  const std::string problem = camera.Validate();
  if (!problem.empty()) throw InputError(file, field, "camera " + std::to_string(camera_id) + ": " + problem);
}

// Cross-checks a freshly read model and sorts its images by name.
void FinishModel(const std::string& images_file, ColmapModel* model) {
  std::set<std::uint32_t> ids;
  for (const ColmapImage& image : model->images) {
    if (!model->cameras.count(image.camera_id))
      throw InputError(
          images_file, ImageLabel(image.image_id, image.name),
          "refers to camera " + std::to_string(image.camera_id) + ", which the model does not define");
    if (!ids.insert(image.image_id).second)
      throw InputError(images_file, ImageLabel(image.image_id, image.name), "duplicate image id");
  }
  std::stable_sort(model->images.begin(), model->images.end(),
                   [](const ColmapImage& a, const ColmapImage& b) { return a.name < b.name; });
  for (size_t i = 1; i < model->images.size(); ++i) {
    if (model->images[i].name == model->images[i - 1].name)
      throw InputError(
          images_file, ImageLabel(model->images[i].image_id, model->images[i].name),
          "duplicate image name (also image " + std::to_string(model->images[i - 1].image_id) + ")");
  }
}

// ---------------------------------------------------------------------------
// Text format

std::string Trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r\n");
  return s.substr(b, e - b + 1);
}

std::vector<std::string> Split(const std::string& s) {
  std::vector<std::string> out;
  std::istringstream in(s);
  std::string token;
  while (in >> token) out.push_back(token);
  return out;
}

bool ParseDouble(const std::string& s, double* value) {
  if (s.empty()) return false;
  char* end = nullptr;
  errno = 0;
  *value = std::strtod(s.c_str(), &end);
  return end == s.c_str() + s.size();
}

bool ParseUint(const std::string& s, std::uint64_t max_value, std::uint64_t* value) {
  if (s.empty() || s[0] == '-' || s[0] == '+') return false;
  char* end = nullptr;
  errno = 0;
  const unsigned long long v = std::strtoull(s.c_str(), &end, 10);
  if (end != s.c_str() + s.size() || errno == ERANGE || v > max_value) return false;
  *value = v;
  return true;
}

class TextLines {
 public:
  explicit TextLines(const fs::path& path) : path_(path.string()), in_(path) {
    if (!in_) throw InputError(path_, "cannot open file");
  }
  // Next non-empty, non-comment line (trimmed); false at the end.
  bool NextData(std::string* line) {
    while (NextRaw(line)) {
      if (!line->empty() && (*line)[0] != '#') return true;
    }
    return false;
  }
  // Next line whatever it holds (trimmed).
  bool NextRaw(std::string* line) {
    if (!std::getline(in_, *line)) return false;
    ++line_number_;
    *line = Trim(*line);
    return true;
  }
  std::string Field() const { return "line " + std::to_string(line_number_); }
  const std::string& path() const { return path_; }
  int line_number() const { return line_number_; }

  double Double(const std::string& token, const char* what) const {
    double v = 0;
    if (!ParseDouble(token, &v))
      throw InputError(path_, Field(), std::string(what) + ": " + InputToken(token) + " is not a number");
    return v;
  }
  std::uint64_t Uint(const std::string& token, std::uint64_t max_value, const char* what) const {
    std::uint64_t v = 0;
    if (!ParseUint(token, max_value, &v))
      throw InputError(path_, Field(),
                       std::string(what) + ": " + InputToken(token) + " is not a valid unsigned integer");
    return v;
  }

 private:
  std::string path_;
  std::ifstream in_;
  int line_number_ = 0;
};

void ReadCamerasText(const fs::path& path, ColmapModel* model) {
  TextLines lines(path);
  std::string line;
  while (lines.NextData(&line)) {
    const std::vector<std::string> tok = Split(line);
    if (tok.size() < 4)
      throw InputError(lines.path(), lines.Field(),
                       "expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[], got " + std::to_string(tok.size()) +
                           " fields");
    const auto id = static_cast<std::uint32_t>(
        lines.Uint(tok[0], std::numeric_limits<std::uint32_t>::max(), "CAMERA_ID"));
    Camera camera;
    try {
      camera.model = CameraModelFromName(tok[1]);
    } catch (const std::invalid_argument&) {
      throw InputError(lines.path(), lines.Field(),
                       "camera " + std::to_string(id) + ": unsupported camera model " + InputToken(tok[1]));
    }
    camera.width = static_cast<int>(lines.Uint(tok[2], std::numeric_limits<int>::max(), "WIDTH"));
    camera.height = static_cast<int>(lines.Uint(tok[3], std::numeric_limits<int>::max(), "HEIGHT"));
    const size_t num_params = NumCameraParams(camera.model);
    if (tok.size() - 4 != num_params)
      throw InputError(lines.path(), lines.Field(),
                       "camera " + std::to_string(id) + ": " + tok[1] + " needs " +
                           std::to_string(num_params) + " parameters, got " + std::to_string(tok.size() - 4));
    for (size_t k = 0; k < num_params; ++k) camera.params.push_back(lines.Double(tok[4 + k], "PARAMS"));
    CheckCamera(lines.path(), lines.Field(), id, camera);
    if (!model->cameras.emplace(id, camera).second)
      throw InputError(lines.path(), lines.Field(), "duplicate camera id " + std::to_string(id));
  }
}

// A POINTS2D line is a multiple of three numbers; anything else is the next image line.
bool IsPoints2DLine(const std::string& line) {
  const std::vector<std::string> tok = Split(line);
  if (tok.size() % 3 != 0) return false;
  double v;
  for (const std::string& t : tok)
    if (!ParseDouble(t, &v)) return false;
  return true;
}

void ReadImagesText(const fs::path& path, ColmapModel* model) {
  TextLines lines(path);
  std::string line;
  std::string pending;  // an image line met where a POINTS2D line was expected
  bool have_pending = false;
  while (true) {
    if (have_pending) {
      line = pending;
      have_pending = false;
    } else if (!lines.NextData(&line)) {
      break;
    }
    const std::string field = lines.Field();
    // IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME; the name is the rest of the line.
    std::istringstream in(line);
    std::vector<std::string> tok(9);
    for (auto& t : tok) in >> t;
    std::string name;
    std::getline(in, name);
    name = Trim(name);
    if (tok[8].empty() || name.empty())
      throw InputError(lines.path(), field,
                       "expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME (fields missing)");
    ColmapImage image;
    image.name = name;
    image.image_id =
        static_cast<std::uint32_t>(lines.Uint(tok[0], std::numeric_limits<std::uint32_t>::max(), "IMAGE_ID"));
    double v[7];
    static const char* kNames[7] = {"QW", "QX", "QY", "QZ", "TX", "TY", "TZ"};
    for (int k = 0; k < 7; ++k) v[k] = lines.Double(tok[1 + k], kNames[k]);
    image.camera_id = static_cast<std::uint32_t>(
        lines.Uint(tok[8], std::numeric_limits<std::uint32_t>::max(), "CAMERA_ID"));
    image.cam_from_world =
        MakePose(lines.path(), field, image.image_id, image.name, v[0], v[1], v[2], v[3], v[4], v[5], v[6]);
    model->images.push_back(std::move(image));
    // COLMAP writes a POINTS2D line (possibly empty) after every image line;
    // tolerate writers that leave it out.
    std::string points;
    if (lines.NextRaw(&points) && !points.empty() && points[0] != '#' && !IsPoints2DLine(points)) {
      pending = points;
      have_pending = true;
    }
  }
}

std::size_t CountPoints3DText(const fs::path& path) {
  TextLines lines(path);
  std::string line;
  std::size_t n = 0;
  while (lines.NextData(&line)) ++n;
  return n;
}

// ---------------------------------------------------------------------------
// Binary format (little-endian, as COLMAP writes it on every platform it supports)

class BinaryReader {
 public:
  explicit BinaryReader(const fs::path& path) : path_(path.string()), in_(path, std::ios::binary) {
    if (!in_) throw InputError(path_, "cannot open file");
    in_.seekg(0, std::ios::end);
    size_ = static_cast<std::uint64_t>(in_.tellg());
    in_.seekg(0);
  }
  const std::string& path() const { return path_; }
  std::uint64_t Remaining() const { return size_ - pos_; }

  void Need(std::uint64_t bytes, const std::string& field) {
    if (bytes > Remaining())
      throw InputError(path_, field,
                       "file is truncated: need " + std::to_string(bytes) + " bytes at offset " +
                           std::to_string(pos_) + ", only " + std::to_string(Remaining()) +
                           " left (file size " + std::to_string(size_) + ")");
  }
  template <typename T>
  T Read(const std::string& field) {
    Need(sizeof(T), field);
    T value;
    in_.read(reinterpret_cast<char*>(&value), sizeof(T));
    if (!in_) throw InputError(path_, field, "read failed at offset " + std::to_string(pos_));
    pos_ += sizeof(T);
    return value;
  }
  void Skip(std::uint64_t bytes, const std::string& field) {
    Need(bytes, field);
    in_.seekg(static_cast<std::streamoff>(bytes), std::ios::cur);
    pos_ += bytes;
  }
  std::string ReadCString(const std::string& field) {
    std::string s;
    while (true) {
      const char c = Read<char>(field);
      if (c == '\0') return s;
      s.push_back(c);
      if (s.size() > 4096) throw InputError(path_, field, "name longer than 4096 bytes (corrupt file?)");
    }
  }
  // A count whose entries take at least `min_entry_bytes` each must fit in
  // what is left of the file; this keeps corrupt counts from allocating.
  std::uint64_t ReadCount(const std::string& field, std::uint64_t min_entry_bytes) {
    const auto n = Read<std::uint64_t>(field);
    if (min_entry_bytes > 0 && n > Remaining() / min_entry_bytes)
      throw InputError(path_, field,
                       "count " + std::to_string(n) + " needs at least " + std::to_string(min_entry_bytes) +
                           " bytes each but only " + std::to_string(Remaining()) +
                           " bytes are left (truncated or corrupt)");
    return n;
  }
  void WarnTrailing() const {
    if (Remaining() > 0) spdlog::warn("{}: {} unexpected bytes after the last entry", path_, Remaining());
  }

 private:
  std::string path_;
  std::ifstream in_;
  std::uint64_t size_ = 0;
  std::uint64_t pos_ = 0;
};

void ReadCamerasBinary(const fs::path& path, ColmapModel* model) {
  BinaryReader in(path);
  constexpr std::uint64_t kMinCamera = 4 + 4 + 8 + 8 + 3 * 8;
  const std::uint64_t n = in.ReadCount("number of cameras", kMinCamera);
  for (std::uint64_t i = 0; i < n; ++i) {
    const std::string entry = "camera #" + std::to_string(i);
    const auto id = in.Read<std::uint32_t>(entry + " camera_id");
    const std::string field = "camera " + std::to_string(id);
    const auto model_id = in.Read<std::int32_t>(field + " model_id");
    if (!IsSupportedCameraModelId(model_id))
      throw InputError(
          in.path(), field,
          "unsupported camera model id " + std::to_string(model_id) +
              " (supported: 0-4 and 6: SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, OPENCV, FULL_OPENCV)");
    Camera camera;
    camera.model = static_cast<CameraModelId>(model_id);
    const auto width = in.Read<std::uint64_t>(field + " width");
    const auto height = in.Read<std::uint64_t>(field + " height");
    constexpr std::uint64_t kMaxSide = std::numeric_limits<int>::max();
    if (width > kMaxSide || height > kMaxSide)
      throw InputError(
          in.path(), field,
          "image size " + std::to_string(width) + "x" + std::to_string(height) + " is not plausible");
    camera.width = static_cast<int>(width);
    camera.height = static_cast<int>(height);
    camera.params.resize(NumCameraParams(camera.model));
    for (double& p : camera.params) p = in.Read<double>(field + " params");
    CheckCamera(in.path(), field, id, camera);
    if (!model->cameras.emplace(id, camera).second)
      throw InputError(in.path(), field, "duplicate camera id " + std::to_string(id));
  }
  in.WarnTrailing();
}

void ReadImagesBinary(const fs::path& path, ColmapModel* model) {
  BinaryReader in(path);
  constexpr std::uint64_t kMinImage = 4 + 7 * 8 + 4 + 1 + 8;
  const std::uint64_t n = in.ReadCount("number of images", kMinImage);
  model->images.reserve(n);
  for (std::uint64_t i = 0; i < n; ++i) {
    ColmapImage image;
    image.image_id = in.Read<std::uint32_t>("image #" + std::to_string(i) + " image_id");
    const std::string id_field = ImageLabel(image.image_id, "");
    double v[7];
    for (double& x : v) x = in.Read<double>(id_field + " pose");
    image.camera_id = in.Read<std::uint32_t>(id_field + " camera_id");
    image.name = in.ReadCString(id_field + " name");
    const std::string field = ImageLabel(image.image_id, image.name);
    if (image.name.empty()) throw InputError(in.path(), field, "empty image name");
    const std::uint64_t num_points2D = in.ReadCount(field + " num_points2D", 24);
    in.Skip(num_points2D * 24, field + " points2D");  // x, y (double), point3D_id (uint64)
    image.cam_from_world =
        MakePose(in.path(), field, image.image_id, image.name, v[0], v[1], v[2], v[3], v[4], v[5], v[6]);
    model->images.push_back(std::move(image));
  }
  in.WarnTrailing();
}

std::size_t CountPoints3DBinary(const fs::path& path) {
  BinaryReader in(path);
  constexpr std::uint64_t kMinPoint = 8 + 3 * 8 + 3 + 8 + 8;
  const std::uint64_t n = in.ReadCount("number of points", kMinPoint);
  // Walk the tracks so that a truncated file is reported, not silently miscounted.
  for (std::uint64_t i = 0; i < n; ++i) {
    const std::string field = "point #" + std::to_string(i);
    in.Skip(8 + 3 * 8 + 3 + 8, field);
    const std::uint64_t track = in.ReadCount(field + " track_length", 8);
    in.Skip(track * 8, field + " track");
  }
  in.WarnTrailing();
  return n;
}

bool HasFile(const fs::path& dir, const char* name) {
  std::error_code ec;
  return fs::is_regular_file(dir / name, ec);
}

std::ofstream OpenForWrite(const fs::path& path, bool binary) {
  std::ofstream out(path, binary ? std::ios::binary | std::ios::trunc : std::ios::trunc);
  if (!out) throw InputError(path.string(), "cannot open file for writing");
  return out;
}

void CloseChecked(std::ofstream& out, const fs::path& path) {
  out.close();
  if (!out) throw InputError(path.string(), "write failed");
}

void CreateDir(const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  if (ec) throw InputError(dir.string(), "cannot create folder: " + ec.message());
}

template <typename T>
void Put(std::ofstream& out, T value) {
  out.write(reinterpret_cast<const char*>(&value), sizeof(T));
}

}  // namespace

fs::path FindColmapModel(const fs::path& dir) {
  for (const fs::path& candidate : {dir, dir / "sparse", dir / "sparse" / "0"}) {
    if ((HasFile(candidate, "cameras.txt") && HasFile(candidate, "images.txt")) ||
        (HasFile(candidate, "cameras.bin") && HasFile(candidate, "images.bin")))
      return candidate;
  }
  return {};
}

bool IsColmapModelBinary(const fs::path& model_dir) {
  return HasFile(model_dir, "cameras.bin") && HasFile(model_dir, "images.bin");
}

ColmapModel ReadColmapModel(const fs::path& model_dir) {
  if (IsColmapModelBinary(model_dir)) return ReadColmapModelBinary(model_dir);
  if (HasFile(model_dir, "cameras.txt") && HasFile(model_dir, "images.txt"))
    return ReadColmapModelText(model_dir);
  std::error_code ec;
  if (!fs::is_directory(model_dir, ec))
    throw InputError(model_dir.string(), "COLMAP model folder does not exist");
  throw InputError(model_dir.string(),
                   "not a COLMAP model: expected cameras.txt + images.txt or cameras.bin + images.bin");
}

ColmapModel ReadColmapModelText(const fs::path& model_dir) {
  ColmapModel model;
  ReadCamerasText(model_dir / "cameras.txt", &model);
  ReadImagesText(model_dir / "images.txt", &model);
  FinishModel((model_dir / "images.txt").string(), &model);
  if (HasFile(model_dir, "points3D.txt")) model.num_points3D = CountPoints3DText(model_dir / "points3D.txt");
  spdlog::debug("{}: {} cameras, {} images, {} points (text)", model_dir.string(), model.cameras.size(),
                model.images.size(), model.num_points3D);
  return model;
}

ColmapModel ReadColmapModelBinary(const fs::path& model_dir) {
  ColmapModel model;
  ReadCamerasBinary(model_dir / "cameras.bin", &model);
  ReadImagesBinary(model_dir / "images.bin", &model);
  FinishModel((model_dir / "images.bin").string(), &model);
  if (HasFile(model_dir, "points3D.bin"))
    model.num_points3D = CountPoints3DBinary(model_dir / "points3D.bin");
  spdlog::debug("{}: {} cameras, {} images, {} points (binary)", model_dir.string(), model.cameras.size(),
                model.images.size(), model.num_points3D);
  return model;
}

void WriteColmapModelText(const ColmapModel& model, const fs::path& model_dir) {
  CreateDir(model_dir);
  {
    const fs::path path = model_dir / "cameras.txt";
    std::ofstream out = OpenForWrite(path, false);
    out << std::setprecision(17);
    out << "# Camera list with one line of data per camera:\n"
        << "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n"
        << "# Number of cameras: " << model.cameras.size() << "\n";
    for (const auto& [id, camera] : model.cameras) {
      out << id << " " << CameraModelName(camera.model) << " " << camera.width << " " << camera.height;
      for (double p : camera.params) out << " " << p;
      out << "\n";
    }
    CloseChecked(out, path);
  }
  {
    const fs::path path = model_dir / "images.txt";
    std::ofstream out = OpenForWrite(path, false);
    out << std::setprecision(17);
    out << "# Image list with two lines of data per image:\n"
        << "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n"
        << "#   POINTS2D[] as (X, Y, POINT3D_ID)\n"
        << "# Number of images: " << model.images.size() << ", mean observations per image: 0\n";
    for (const ColmapImage& image : model.images) {
      const Eigen::Quaterniond& q = image.cam_from_world.rotation;
      const Eigen::Vector3d& t = image.cam_from_world.translation;
      out << image.image_id << " " << q.w() << " " << q.x() << " " << q.y() << " " << q.z() << " " << t.x()
          << " " << t.y() << " " << t.z() << " " << image.camera_id << " " << image.name << "\n\n";
    }
    CloseChecked(out, path);
  }
  {
    const fs::path path = model_dir / "points3D.txt";
    std::ofstream out = OpenForWrite(path, false);
    out << "# 3D point list with one line of data per point:\n"
        << "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n"
        << "# Number of points: 0, mean track length: 0\n";
    CloseChecked(out, path);
  }
}

void WriteColmapModelBinary(const ColmapModel& model, const fs::path& model_dir) {
  CreateDir(model_dir);
  {
    const fs::path path = model_dir / "cameras.bin";
    std::ofstream out = OpenForWrite(path, true);
    Put<std::uint64_t>(out, model.cameras.size());
    for (const auto& [id, camera] : model.cameras) {
      Put<std::uint32_t>(out, id);
      Put<std::int32_t>(out, static_cast<std::int32_t>(camera.model));
      Put<std::uint64_t>(out, static_cast<std::uint64_t>(camera.width));
      Put<std::uint64_t>(out, static_cast<std::uint64_t>(camera.height));
      for (double p : camera.params) Put<double>(out, p);
    }
    CloseChecked(out, path);
  }
  {
    const fs::path path = model_dir / "images.bin";
    std::ofstream out = OpenForWrite(path, true);
    Put<std::uint64_t>(out, model.images.size());
    for (const ColmapImage& image : model.images) {
      const Eigen::Quaterniond& q = image.cam_from_world.rotation;
      const Eigen::Vector3d& t = image.cam_from_world.translation;
      Put<std::uint32_t>(out, image.image_id);
      for (double v : {q.w(), q.x(), q.y(), q.z(), t.x(), t.y(), t.z()}) Put<double>(out, v);
      Put<std::uint32_t>(out, image.camera_id);
      out.write(image.name.c_str(), static_cast<std::streamsize>(image.name.size() + 1));  // with the NUL
      Put<std::uint64_t>(out, 0);                                                          // no 2D points
    }
    CloseChecked(out, path);
  }
  {
    const fs::path path = model_dir / "points3D.bin";
    std::ofstream out = OpenForWrite(path, true);
    Put<std::uint64_t>(out, 0);
    CloseChecked(out, path);
  }
}

}  // namespace lfrecon
