#include "job_store.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>
#include <random>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "io/frame_source.h"
#include "util/error.h"

namespace lfrecon::svc {
namespace fs = std::filesystem;

namespace {

std::string Stem(int index) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%06d.pb", index);
  return buf;
}

const char* KindDir(pb::MapKind kind) {
  switch (kind) {
    case pb::MAP_SPARSE: return "sparse";
    case pb::MAP_FILTERED:
    case pb::MAP_DENSE: return "dense";
    default: throw std::invalid_argument("map kind " + std::to_string(static_cast<int>(kind)));
  }
}

template <typename T>
void ParseFile(const fs::path& path, T* msg) {
  const std::string bytes = ReadFileBytes(path);
  if (!msg->ParseFromString(bytes)) throw InputError(path.string(), "not a valid " + msg->GetTypeName() + " message");
}

}  // namespace

namespace {

[[noreturn]] void ThrowErrno(const fs::path& path, const std::string& what, int err) {
  throw InputError(path.string(), what + ": " + std::strerror(err));
}

void FsyncDir(const fs::path& dir) {
  const int fd = ::open(dir.empty() ? "." : dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) ThrowErrno(dir, "cannot open folder to sync it", errno);
  const int rc = ::fsync(fd);
  const int err = errno;
  ::close(fd);
  if (rc != 0) ThrowErrno(dir, "cannot sync folder", err);
}

void WriteAll(int fd, const char* data, std::size_t size, const fs::path& path) {
  while (size > 0) {
    const ssize_t n = ::write(fd, data, size);
    if (n < 0 && errno == EINTR) continue;
    if (n < 0) ThrowErrno(path, "cannot write", errno);
    data += n;
    size -= static_cast<std::size_t>(n);
  }
}

}  // namespace

fs::path TempPathFor(const fs::path& path) {
  static std::atomic<unsigned> counter{0};
  return path.string() + ".tmp" + std::to_string(::getpid()) + "_" + std::to_string(counter++);
}

void CommitFile(const fs::path& tmp, const fs::path& path) {
  try {
    const int fd = ::open(tmp.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) ThrowErrno(tmp, "cannot open", errno);
    const int rc = ::fsync(fd);
    const int err = errno;
    ::close(fd);
    if (rc != 0) ThrowErrno(tmp, "cannot sync", err);
    if (::rename(tmp.c_str(), path.c_str()) != 0) ThrowErrno(path, "cannot rename " + tmp.string() + " to it", errno);
  } catch (...) {
    ::unlink(tmp.c_str());
    throw;
  }
  FsyncDir(path.parent_path());
}

void WriteFileAtomic(const fs::path& path, const std::string& bytes) {
  fs::create_directories(path.parent_path());
  const fs::path tmp = TempPathFor(path);
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) ThrowErrno(tmp, "cannot create", errno);
  try {
    WriteAll(fd, bytes.data(), bytes.size(), tmp);
    if (::fsync(fd) != 0) ThrowErrno(tmp, "cannot sync", errno);
  } catch (...) {
    ::close(fd);
    ::unlink(tmp.c_str());  // no temporary file is left behind (a full disk used to collect thousands)
    throw;
  }
  if (::close(fd) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    ThrowErrno(tmp, "cannot write", err);
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    ThrowErrno(path, "cannot rename " + tmp.string() + " to it", err);
  }
  FsyncDir(path.parent_path());
}

std::string ReadFileBytes(const fs::path& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path.string(), "cannot read");
  std::ostringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

FileLock::FileLock(const fs::path& file) {
  std::error_code ec;
  const bool dir = fs::is_directory(file, ec);
  fd_ = dir ? ::open(file.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC)
            : ::open(file.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0644);
  if (fd_ < 0) ThrowErrno(file, "cannot open lock file", errno);
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    ::close(fd_);
    fd_ = -1;
    if (err == EWOULDBLOCK) throw std::runtime_error(file.string() + " is locked by another process");
    ThrowErrno(file, "cannot lock", err);
  }
  const std::string pid = std::to_string(::getpid()) + "\n";  // who holds it, for people
  if (!dir && ::ftruncate(fd_, 0) == 0) (void)!::write(fd_, pid.data(), pid.size());
}

FileLock::~FileLock() {
  if (fd_ >= 0) ::close(fd_);
}

std::unique_ptr<FileLock> LockStoreForIngest(const JobStore& store) {
  try {
    return std::make_unique<FileLock>(store.root() / kIngestLockName);
  } catch (const std::runtime_error& e) {
    throw std::runtime_error("another lfrecon-ingest serves the job store " + store.root().string() + " (" +
                             e.what() + ")");
  }
}

bool IsTempFileName(const std::string& name) {
  const auto at = name.rfind(".tmp");
  if (at == std::string::npos || at == 0) return false;
  const std::string tail = name.substr(at + 4);  // "<pid>_<n>"
  const auto underscore = tail.find('_');
  if (underscore == std::string::npos || underscore == 0 || underscore + 1 == tail.size()) return false;
  for (std::size_t i = 0; i < tail.size(); ++i)
    if (i != underscore && !std::isdigit(static_cast<unsigned char>(tail[i]))) return false;
  return true;
}

int RemoveIngestTempFiles(const JobStore& store) {
  int removed = 0;
  std::error_code ec;
  auto sweep = [&](const fs::path& dir, bool any) {
    std::error_code e2;
    for (const auto& e : fs::directory_iterator(dir, e2)) {
      const std::string name = e.path().filename().string();
      if (!IsTempFileName(name)) continue;
      const std::string target = name.substr(0, name.rfind(".tmp"));
      if (!any && target != "manifest.pb" && target != "ingest.done") continue;  // the aggregator's are its own
      if (fs::remove(e.path(), e2)) ++removed;
    }
  };
  for (const auto& e : fs::directory_iterator(store.root(), ec)) {
    if (!JobStore::ValidJobId(e.path().filename().string()) || !e.is_directory(ec)) continue;
    sweep(e.path(), false);
    sweep(e.path() / "frames", true);
  }
  return removed;
}

JobStore::JobStore(fs::path root) : root_(std::move(root)) { fs::create_directories(root_); }

bool JobStore::ValidJobId(const std::string& id) {
  if (id.empty() || id.size() > 64) return false;
  for (char c : id)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-')) return false;
  return true;
}

fs::path JobStore::JobDir(const std::string& id) const {
  if (!ValidJobId(id)) throw std::invalid_argument("invalid job id '" + id + "'");
  return root_ / id;
}

bool JobStore::Exists(const std::string& id) const {
  return ValidJobId(id) && fs::exists(root_ / id / "manifest.pb");
}

std::string JobStore::CreateJob() {
  std::random_device rd;
  std::mt19937_64 rng((static_cast<std::uint64_t>(rd()) << 32) ^ rd() ^ static_cast<std::uint64_t>(::getpid()));
  const auto now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  char stamp[32];
  std::strftime(stamp, sizeof(stamp), "%Y%m%d-%H%M%S", std::localtime(&now));
  for (int attempt = 0; attempt < 100; ++attempt) {
    char id[64];
    std::snprintf(id, sizeof(id), "j%s-%06llx", stamp, static_cast<unsigned long long>(rng() & 0xffffff));
    std::error_code ec;
    if (fs::create_directory(root_ / id, ec)) return id;
  }
  throw std::runtime_error("cannot create a job folder under " + root_.string());
}

void JobStore::WriteManifest(const pb::JobManifest& manifest) const {
  WriteFileAtomic(JobDir(manifest.job_id()) / "manifest.pb", manifest.SerializeAsString());
}

pb::JobManifest JobStore::ReadManifest(const std::string& id) const {
  pb::JobManifest m;
  ParseFile(JobDir(id) / "manifest.pb", &m);
  return m;
}

fs::path JobStore::FramePath(const std::string& id, int index) const { return JobDir(id) / "frames" / Stem(index); }
fs::path JobStore::MapPath(const std::string& id, pb::MapKind kind, int view) const {
  return JobDir(id) / KindDir(kind) / Stem(view);
}

void JobStore::WriteFrame(const std::string& id, const pb::Frame& frame) const {
  WriteFileAtomic(FramePath(id, static_cast<int>(frame.index())), frame.SerializeAsString());
}

// The stored Frame of `index`, checked to be that frame.
static pb::Frame ReadStoredFrame(const fs::path& path, int index) {
  pb::Frame f;
  ParseFile(path, &f);
  if (static_cast<int>(f.index()) != index) throw InputError(path.string(), "index", "holds frame " + std::to_string(f.index()));
  return f;
}

cv::Mat JobStore::ReadFrame(const std::string& id, int index, const PinholeView& expect) const {
  const fs::path path = FramePath(id, index);
  return FrameFromProto(ReadStoredFrame(path, index), expect.width, expect.height, path.string());
}

cv::Mat JobStore::ReadMask(const std::string& id, int index, const PinholeView& expect) const {
  const fs::path path = FramePath(id, index);
  return MaskFromProto(ReadStoredFrame(path, index), expect.width, expect.height, path.string());
}

void JobStore::WriteMap(const std::string& id, const pb::DepthMap& map) const {
  WriteFileAtomic(MapPath(id, map.kind(), static_cast<int>(map.view())), map.SerializeAsString());
}

DepthMap JobStore::ReadMap(const std::string& id, pb::MapKind kind, int view, const PinholeView& expect,
                           cv::Mat* own) const {
  const fs::path path = MapPath(id, kind, view);
  pb::DepthMap m;
  ParseFile(path, &m);
  return DepthMapFromProto(m, expect.width, expect.height, path.string(), own);
}

void JobStore::WriteText(const std::string& id, const std::string& name, const std::string& text) const {
  WriteFileAtomic(JobDir(id) / name, text);
}

std::optional<std::string> JobStore::ReadText(const std::string& id, const std::string& name) const {
  const fs::path p = JobDir(id) / name;
  if (!fs::exists(p)) return std::nullopt;
  return ReadFileBytes(p);
}

void JobStore::AppendLine(const std::string& id, const std::string& name, const std::string& line) const {
  const fs::path path = JobDir(id) / name;
  const int fd = ::open(path.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
  if (fd < 0) ThrowErrno(path, "cannot append", errno);
  const std::string text = line + "\n";
  try {
    WriteAll(fd, text.data(), text.size(), path);
    if (::fsync(fd) != 0) ThrowErrno(path, "cannot sync", errno);
  } catch (...) {
    ::close(fd);
    throw;
  }
  ::close(fd);
}

// ---- conversions ---------------------------------------------------------------------

pb::Camera CameraToProto(const PinholeView& view, const std::string& name) {
  pb::Camera c;
  c.set_width(view.width);
  c.set_height(view.height);
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k) {
      c.add_k(view.K(r, k));
      c.add_r(view.R(r, k));
    }
  for (int r = 0; r < 3; ++r) c.add_t(view.t(r));
  c.set_name(name);
  return c;
}

PinholeView CameraFromProto(const pb::Camera& c, const std::string& what) {
  if (c.k_size() != 9 || c.r_size() != 9 || c.t_size() != 3)
    throw InputError(what, "camera", "needs 9 K, 9 R and 3 t values");
  if (c.width() == 0 || c.height() == 0 || c.width() > 65536 || c.height() > 65536)
    throw InputError(what, "camera", "bad size " + std::to_string(c.width()) + "x" + std::to_string(c.height()));
  PinholeView v;
  v.width = static_cast<int>(c.width());
  v.height = static_cast<int>(c.height());
  for (int r = 0; r < 3; ++r) {
    for (int k = 0; k < 3; ++k) {
      v.K(r, k) = c.k(3 * r + k);
      v.R(r, k) = c.r(3 * r + k);
    }
    v.t(r) = c.t(r);
  }
  if (!v.K.allFinite() || !v.R.allFinite() || !v.t.allFinite()) throw InputError(what, "camera", "non-finite value");
  if (std::abs(v.K.determinant()) < 1e-12) throw InputError(what, "camera", "singular K");
  v.K_inv = v.K.inverse();
  return v;
}

pb::Box BoxToProto(const BoundingBox& box) {
  pb::Box b;
  for (int k = 0; k < 3; ++k) {
    b.add_min(box.min(k));
    b.add_max(box.max(k));
  }
  return b;
}

BoundingBox BoxFromProto(const pb::Box& b, const std::string& what) {
  if (b.min_size() != 3 || b.max_size() != 3) throw InputError(what, "volume", "needs 3 min and 3 max values");
  BoundingBox box;
  box.min = Eigen::Vector3d(b.min(0), b.min(1), b.min(2));
  box.max = Eigen::Vector3d(b.max(0), b.max(1), b.max(2));
  if (!box.IsValid()) throw InputError(what, "volume", "empty or not finite");
  return box;
}

namespace {

// zlib level 3 with its default strategy: on 640x360 MJPG video frames 1.12 bytes a
// pixel at 29 ms a frame, against 1.39 for OpenCV's default (level 1, run-length
// strategy) and 1.02 at 605 ms for level 9 (docs/benchmarks.md).
std::string EncodePng(const cv::Mat& u8, const std::string& what) {
  std::vector<uchar> buf;
  const std::vector<int> params = {cv::IMWRITE_PNG_COMPRESSION, 3, cv::IMWRITE_PNG_STRATEGY,
                                   cv::IMWRITE_PNG_STRATEGY_DEFAULT};
  try {
    if (!cv::imencode(".png", u8, buf, params)) throw InputError(what, "cannot encode the frame as PNG");
  } catch (const cv::Exception& e) {
    throw InputError(what, std::string("cannot encode the frame as PNG: ") + e.what());
  }
  return std::string(buf.begin(), buf.end());
}

}  // namespace

pb::Frame FrameToProto(int index, const cv::Mat& image, const pb::Camera& camera) {
  if (image.type() != CV_32FC3) throw std::invalid_argument("frame must be CV_32FC3");
  pb::Frame f;
  f.set_index(index);
  *f.mutable_camera() = camera;
  const cv::Mat compact = CompactFrame(image);
  if (compact.depth() == CV_8U) {
    f.set_encoding("png");
    f.set_data(EncodePng(compact, "frame " + std::to_string(index)));
    return f;
  }
  f.set_encoding("f32-bgr");
  const cv::Mat c = image.isContinuous() ? image : image.clone();
  f.set_data(c.data, c.total() * c.elemSize());
  return f;
}

pb::SourceCamera SourceCameraToProto(const Camera& camera, int stored_width, int stored_height) {
  pb::SourceCamera s;
  s.set_model(CameraModelName(camera.model));
  s.set_width(static_cast<std::uint32_t>(camera.width));
  s.set_height(static_cast<std::uint32_t>(camera.height));
  for (double p : camera.params) s.add_params(p);
  s.set_stored_width(static_cast<std::uint32_t>(stored_width));
  s.set_stored_height(static_cast<std::uint32_t>(stored_height));
  return s;
}

Camera SourceCameraFromProto(const pb::SourceCamera& s, const std::string& what) {
  Camera c;
  try {
    c.model = CameraModelFromName(s.model());
  } catch (const std::invalid_argument& e) {
    throw InputError(what, "source.model", e.what());
  }
  auto in_range = [](std::uint32_t v) { return v > 0 && v <= 65536; };
  if (!in_range(s.width()) || !in_range(s.height()) || !in_range(s.stored_width()) || !in_range(s.stored_height()))
    throw InputError(what, "source", "sizes must be 1..65536");
  // A downscale only (--max-image-size): never larger than the stored image.
  if (s.width() > s.stored_width() || s.height() > s.stored_height())
    throw InputError(what, "source", "read size larger than the stored image");
  c.width = static_cast<int>(s.width());
  c.height = static_cast<int>(s.height());
  c.params.assign(s.params().begin(), s.params().end());
  const std::string bad = c.Validate();
  if (!bad.empty()) throw InputError(what, "source", bad);
  return c;
}

cv::Mat FrameFromProto(const pb::Frame& f, int width, int height, const std::string& what) {
  if (f.encoding() == "png" || f.encoding() == "jpeg") {
    if (!f.has_source()) return DecodeImageFloat(f.data(), what, cv::Size(width, height));
    const Camera source = SourceCameraFromProto(f.source(), what);
    if (source.width != width || source.height != height)
      throw InputError(what, "source", "read at " + std::to_string(source.width) + "x" + std::to_string(source.height) +
                                           ", its view is " + std::to_string(width) + "x" + std::to_string(height));
    const cv::Mat stored = DecodeImageFloat(
        f.data(), what, cv::Size(static_cast<int>(f.source().stored_width()), static_cast<int>(f.source().stored_height())));
    try {
      return PrepareFrame(stored, source);
    } catch (const std::exception& e) {
      throw InputError(what, std::string("cannot prepare the frame: ") + e.what());
    }
  }
  if (f.encoding() != "f32-bgr") throw InputError(what, "encoding", "unknown frame encoding '" + f.encoding() + "'");
  const std::size_t want = static_cast<std::size_t>(width) * height * 3 * sizeof(float);
  if (f.data().size() != want)
    throw InputError(what, "data", std::to_string(f.data().size()) + " bytes for a " + std::to_string(width) + "x" +
                                       std::to_string(height) + " frame (" + std::to_string(want) + " expected)");
  cv::Mat image(height, width, CV_32FC3);
  std::memcpy(image.data, f.data().data(), want);
  return image;
}

cv::Mat MaskFromProto(const pb::Frame& f, int width, int height, const std::string& what) {
  const std::string& bytes = f.mask();
  if (bytes.empty()) return cv::Mat();
  auto size_text = [](int w, int h) { return std::to_string(w) + "x" + std::to_string(h); };
  // The size from the PNG header before any pixel is decoded: a mask decodes to at most its frame's pixels.
  const auto header = ReadImageHeader(bytes);
  if (!header || header->format != "png")
    throw InputError(what, "mask", "not PNG data (" + std::to_string(bytes.size()) + " bytes)");
  if (header->width != width || header->height != height)
    throw InputError(what, "mask", "mask is " + size_text(header->width, header->height) + ", its frame " +
                                       size_text(width, height));
  if (bytes.size() > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw InputError(what, "mask", "larger than 2 GiB");
  cv::Mat mask;
  try {
    mask = cv::imdecode(cv::Mat(1, static_cast<int>(bytes.size()), CV_8U, const_cast<char*>(bytes.data())),
                        cv::IMREAD_UNCHANGED | cv::IMREAD_IGNORE_ORIENTATION);
  } catch (const cv::Exception& e) {
    throw InputError(what, "mask", std::string("cannot be decoded: ") + e.what());
  }
  if (mask.empty()) throw InputError(what, "mask", "PNG data that does not decode");
  if (mask.type() != CV_8UC1)
    throw InputError(what, "mask", "must be 8-bit with one channel (" + std::to_string(mask.channels()) +
                                       " channels, depth " + std::to_string(mask.depth()) + ")");
  if (mask.cols != width || mask.rows != height)
    throw InputError(what, "mask", "decodes to " + size_text(mask.cols, mask.rows) + ", its frame " +
                                       size_text(width, height));
  return mask;
}

std::string MaskToPng(const cv::Mat& mask, const std::string& what) {
  if (mask.type() != CV_8UC1) throw std::invalid_argument("a mask must be CV_8UC1");
  return EncodePng(mask, what + " mask");
}

pb::Frame CompactFrameProto(pb::Frame f, const std::string& what) {
  if (f.encoding() != "bgr8" && f.encoding() != "f32-bgr") return f;
  if (f.has_source()) throw InputError(what, "source", "a raw frame is the frame as read: no source camera");
  const int w = static_cast<int>(f.camera().width()), h = static_cast<int>(f.camera().height());
  const std::size_t elem = f.encoding() == "bgr8" ? 1 : sizeof(float);
  if (w <= 0 || h <= 0 || static_cast<std::int64_t>(w) * h > kMaxImagePixels ||
      f.data().size() != static_cast<std::size_t>(w) * h * 3 * elem)
    throw InputError(what, "data", std::to_string(f.data().size()) + " bytes for a " + std::to_string(w) + "x" +
                                       std::to_string(h) + " " + f.encoding() + " frame");
  if (f.encoding() == "bgr8") {
    const cv::Mat u8(h, w, CV_8UC3, const_cast<char*>(f.data().data()));
    f.set_data(EncodePng(u8, what));
    f.set_encoding("png");
    return f;
  }
  const cv::Mat image(h, w, CV_32FC3, const_cast<char*>(f.data().data()));
  if (!cv::checkRange(image, true)) throw InputError(what, "data", "non-finite values");
  const pb::Camera camera = f.camera();
  return FrameToProto(static_cast<int>(f.index()), image, camera);
}

// ---- frames of a dataset as the store keeps them -------------------------------------

StoreFrameEncoder::StoreFrameEncoder(const Dataset& dataset) : ds_(dataset) {
  if (!ds_.video_path().empty()) video_ = std::make_unique<VideoSource>(ds_.video_path());
}

StoreFrameEncoder::~StoreFrameEncoder() = default;

pb::Frame StoreFrameEncoder::Encode(int k, bool validate) {
  pb::Frame f = EncodeImage(k, validate);
  // The mask as `lfrecon run` reads it (Dataset::ReadMask: at the frame's size, undistorted);
  // a frame without one (an image without alpha among others with it) carries none.
  if (ds_.HasMasks()) {
    const cv::Mat mask = ds_.ReadMask(k);
    if (!mask.empty()) f.set_mask(MaskToPng(mask, "frame " + std::to_string(k)));
  }
  return f;
}

pb::Frame StoreFrameEncoder::EncodeImage(int k, bool validate) {
  const DatasetView& view = ds_.views().at(static_cast<std::size_t>(k));
  pb::Frame f;
  f.set_index(static_cast<std::uint32_t>(k));
  *f.mutable_camera() = CameraToProto(ds_.View(k), view.name);
  const cv::Size stored(view.source_width, view.source_height);
  if (video_) {
    const std::string what = ds_.video_path().string();
    const lfrecon::Frame raw = video_->Read(k);  // sequential reads do not seek
    if (raw.image.cols != stored.width || raw.image.rows != stored.height)
      throw InputError(what, "frame " + std::to_string(k),
                       "image is " + std::to_string(raw.image.cols) + "x" + std::to_string(raw.image.rows) +
                           " but its camera (" + view.name + ") is " + std::to_string(stored.width) + "x" +
                           std::to_string(stored.height));
    const cv::Mat u8 = CompactFrame(raw.image);  // a decoded video frame is 8-bit: exact
    if (u8.depth() != CV_8U) throw InputError(what, "frame " + std::to_string(k), "not an 8-bit frame");
    f.set_encoding("png");
    f.set_data(EncodePng(u8, what + " frame " + std::to_string(k)));
    *f.mutable_source() = SourceCameraToProto(view.camera, stored.width, stored.height);
    return f;
  }
  const fs::path path = ds_.ImagePath(k);
  std::string bytes = ReadFileBytes(path);
  if (const auto header = ReadImageHeader(bytes)) {
    if (validate) DecodeImageFloat(bytes, path.string(), stored);
    f.set_encoding(header->format);
    f.set_data(std::move(bytes));
    *f.mutable_source() = SourceCameraToProto(view.camera, stored.width, stored.height);
    return f;
  }
  if (!prepared_) prepared_ = ds_.OpenFrames();
  const pb::Camera camera = f.camera();
  return FrameToProto(k, prepared_->Read(k).image, camera);
}

pb::DepthMap DepthMapToProto(const DepthMap& map, int view, pb::MapKind kind, const cv::Mat& own) {
  pb::DepthMap m;
  m.set_view(view);
  m.set_kind(kind);
  m.set_width(map.depth.cols);
  m.set_height(map.depth.rows);
  auto put = [](const cv::Mat& mat, int type, std::string* out) {
    if (mat.empty()) return;
    if (mat.type() != type) throw std::invalid_argument("depth map channel of unexpected type");
    const cv::Mat c = mat.isContinuous() ? mat : mat.clone();
    out->assign(reinterpret_cast<const char*>(c.data), c.total() * c.elemSize());
  };
  put(map.depth, CV_32F, m.mutable_depth());
  put(map.confidence, CV_32F, m.mutable_confidence());
  put(map.label, CV_8U, m.mutable_label());
  if (!own.empty() && own.size() != map.depth.size()) throw std::invalid_argument("own-depth mask of another size");
  put(own, CV_8U, m.mutable_own());
  return m;
}

DepthMap DepthMapFromProto(const pb::DepthMap& m, int width, int height, const std::string& what, cv::Mat* own) {
  if (static_cast<int>(m.width()) != width || static_cast<int>(m.height()) != height)
    throw InputError(what, "size", "depth map is " + std::to_string(m.width()) + "x" + std::to_string(m.height()) +
                                       ", its view " + std::to_string(width) + "x" + std::to_string(height));
  const std::size_t n = static_cast<std::size_t>(width) * height;
  auto get = [&](const std::string& bytes, int type, std::size_t elem, const char* field) {
    if (bytes.empty()) return cv::Mat();
    if (bytes.size() != n * elem) throw InputError(what, field, std::to_string(bytes.size()) + " bytes, " +
                                                                    std::to_string(n * elem) + " expected");
    cv::Mat mat(height, width, type);
    std::memcpy(mat.data, bytes.data(), bytes.size());
    return mat;
  };
  DepthMap d;
  d.depth = get(m.depth(), CV_32F, 4, "depth");
  if (d.depth.empty()) throw InputError(what, "depth", "missing");
  d.confidence = get(m.confidence(), CV_32F, 4, "confidence");
  d.label = get(m.label(), CV_8U, 1, "label");
  cv::Mat own_mask = get(m.own(), CV_8U, 1, "own");
  if (own) *own = std::move(own_mask);
  if (cv::checkRange(d.depth, true) == false) throw InputError(what, "depth", "non-finite values");
  if (!d.confidence.empty() && !cv::checkRange(d.confidence, true)) throw InputError(what, "confidence", "non-finite values");
  return d;
}

ReconstructionFlags JobFlags(const pb::JobOptions& o) {
  ReconstructionFlags f;
  f.voxel_size = o.voxel_size();
  f.sigma_s = o.sigma_s();
  f.no_densify = o.no_densify();
  if (o.has_color_views()) f.color_views = o.color_views();
  f.all_views = o.all_views();
  if (o.has_max_frame_gap()) f.max_frame_gap = o.max_frame_gap();
  f.no_mask_free_space = o.no_mask_free_space();
  f.mask_carving = o.mask_carving();
  f.no_geometric_consistency = o.no_geometric_consistency();
  if (o.has_view_step_deg()) f.view_step_deg = o.view_step_deg();
  return f;
}

PipelineOptions JobPipelineOptions(const pb::JobOptions& o) { return OptionsFromFlags(JobFlags(o)); }

FusionOptions JobFusionOptions(const PipelineOptions& po, const BoundingBox& volume) {
  return PipelineFusionOptions(po, volume);
}

pb::JobManifest MakeManifest(const std::string& id, const pb::JobSpec& spec, const Dataset& ds) {
  pb::JobManifest m;
  m.set_job_id(id);
  *m.mutable_spec() = spec;
  for (int i = 0; i < ds.NumViews(); ++i) *m.add_views() = CameraToProto(ds.View(i), ds.views()[i].name);
  *m.mutable_volume() = BoxToProto(ds.bbox());
  m.set_pose_source(ds.pose_source());
  m.set_bbox_source(ds.bbox_source());
  m.set_frame_masks(ds.HasMasks());  // StoreFrameEncoder stores each frame's mask then
  return m;
}

std::optional<BoundingBox> SpecVolume(const pb::JobSpec& spec) {
  if (spec.bbox_size() == 0) return std::nullopt;
  if (spec.bbox_size() != 6) throw OptionError("bbox needs 6 numbers, got " + std::to_string(spec.bbox_size()));
  BoundingBox b;
  b.min = Eigen::Vector3d(spec.bbox(0), spec.bbox(1), spec.bbox(2));
  b.max = Eigen::Vector3d(spec.bbox(3), spec.bbox(4), spec.bbox(5));
  if (!b.IsValid()) throw OptionError("bbox: each max must be greater than its min");
  return b;
}

DatasetOptions ToDatasetOptions(const pb::JobSpec& spec) {
  DatasetOptions d;
  d.dataset_dir = spec.dataset_dir();
  d.images_dir = spec.images_dir();
  d.video_path = spec.video_path();
  d.colmap_dir = spec.colmap_dir();
  d.transforms_path = spec.transforms_path();
  d.masks_dir = spec.masks_dir();
  d.max_image_size = static_cast<int>(std::min<std::uint32_t>(spec.max_image_size(), 1u << 20));
  if (const std::optional<BoundingBox> b = SpecVolume(spec)) d.bbox = *b;
  d.Check();
  return d;
}

JobGeometry LoadJobGeometry(const JobStore& store, const std::string& id) {
  if (!fs::exists(store.JobDir(id) / "manifest.pb") && GrowingStream(store, id)) return LoadStreamGeometry(store, id);
  const pb::JobManifest m = store.ReadManifest(id);
  const std::string what = (store.JobDir(id) / "manifest.pb").string();
  JobGeometry g;
  g.id = id;
  for (const auto& c : m.views()) {
    g.views.push_back(CameraFromProto(c, what));
    g.names.push_back(c.name());
  }
  if (g.views.empty()) throw InputError(what, "views", "no views");
  g.volume = BoxFromProto(m.volume(), what);
  g.frame_masks = !m.has_frame_masks() || m.frame_masks();  // unset (an older store): look at each frame
  g.options = JobPipelineOptions(m.spec().options());
  // Validated with V (the fusion grid), as `lfrecon run` plans its run.
  g.plan = ReconstructionPlan::Compute(g.views, g.volume, g.options);
  return g;
}

std::optional<pb::StreamOpen> GrowingStream(const JobStore& store, const std::string& id) {
  if (!JobStore::ValidJobId(id)) return std::nullopt;
  const fs::path dir = store.JobDir(id);
  if (fs::exists(dir / "manifest.pb") || !fs::exists(dir / "stream.pb")) return std::nullopt;
  pb::StreamOpen open;
  try {
    ParseFile(dir / "stream.pb", &open);
    if (!SpecVolume(open.spec())) return std::nullopt;
  } catch (const std::exception&) {  // ingest checked it at the opening; a stream that cannot grow waits for its end
    return std::nullopt;
  }
  return open;
}

JobGeometry LoadStreamGeometry(const JobStore& store, const std::string& id) {
  const std::optional<pb::StreamOpen> open = GrowingStream(store, id);
  if (!open) throw InputError((store.JobDir(id) / "stream.pb").string(), "not an open stream with V");
  JobGeometry g;
  g.id = id;
  g.open = true;
  g.frame_masks = false;  // until a stored frame carries one (GrowStreamGeometry)
  g.volume = *SpecVolume(open->spec());
  g.options = JobPipelineOptions(open->spec().options());
  g.plan.fusion = JobFusionOptions(g.options, g.volume);
  GrowStreamGeometry(store, &g);
  return g;
}

bool GrowStreamGeometry(const JobStore& store, JobGeometry* g, bool lazy) {
  const std::size_t before = g->views.size();
  for (int k = static_cast<int>(before); store.HasFrame(g->id, k); ++k) {
    const fs::path path = store.FramePath(g->id, k);
    pb::Frame f;
    ParseFile(path, &f);
    g->views.push_back(CameraFromProto(f.camera(), path.string()));
    g->names.push_back(f.camera().name());
    g->frame_masks = g->frame_masks || !f.mask().empty();
  }
  if (g->views.size() == before) return false;
  if (lazy && ReconstructionPlan::SettledDepthFrames(static_cast<int>(g->views.size()), false, g->options) == 0)
    return true;
  // The plan of the prefix, as ReconstructionPlan::Compute on the whole stream gives it for the settled frames.
  g->plan = ReconstructionPlan::Compute(g->views, g->volume, g->options);
  return true;
}

}  // namespace lfrecon::svc
