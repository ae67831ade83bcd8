#include "io/dataset.h"

#include <spdlog/spdlog.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <limits>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <set>

#include "geometry/undistorter.h"
#include "io/colmap_model.h"
#include "io/image_header.h"
#include "io/input_text.h"
#include "io/json_file.h"
#include "io/transforms_json.h"
#include "util/error.h"

namespace lfrecon {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

bool IsDir(const fs::path& p) {
  std::error_code ec;
  return fs::is_directory(p, ec);
}
bool IsFile(const fs::path& p) {
  std::error_code ec;
  return fs::is_regular_file(p, ec);
}

// `path` relative to `dir` if it lies inside it, else empty.
std::string RelativeInside(const fs::path& path, const fs::path& dir) {
  std::error_code ec;
  const fs::path rel = fs::weakly_canonical(path, ec).lexically_relative(fs::weakly_canonical(dir, ec));
  if (ec || rel.empty() || *rel.begin() == "..") return "";
  return rel.generic_string();
}

// transforms.json paths often omit the extension ("images/00000"): try the usual ones.
std::optional<fs::path> ExistingImage(const fs::path& p) {
  if (IsFile(p)) return p;
  for (const char* ext :
       {".png", ".jpg", ".jpeg", ".PNG", ".JPG", ".JPEG", ".exr", ".tif", ".tiff", ".bmp"}) {
    fs::path q = p;
    q += ext;
    if (IsFile(q)) return q;
  }
  return std::nullopt;
}

// The name (relative to `images_dir`) of the image a transforms.json file_path
// refers to. file_path is relative to the transforms file's folder; if that
// does not land in `images_dir`, its trailing components are tried there.
std::string ResolveTransformsImage(const std::string& file_path, const fs::path& base,
                                   const fs::path& images_dir) {
  const fs::path fp = fs::path(file_path).lexically_normal();
  if (auto p = ExistingImage(fp.is_absolute() ? fp : base / fp)) {
    const std::string rel = RelativeInside(*p, images_dir);
    if (!rel.empty()) return rel;
  }
  std::vector<fs::path> parts(fp.begin(), fp.end());
  for (size_t k = 0; k < parts.size(); ++k) {
    fs::path sub;
    for (size_t m = k; m < parts.size(); ++m) sub /= parts[m];
    if (sub.empty() || *sub.begin() == ".." || sub.is_absolute()) continue;
    if (auto p = ExistingImage(images_dir / sub)) return RelativeInside(*p, images_dir);
  }
  return "";
}

// --max-image-size: area averaging, as the camera was scaled (Camera::Scaled).
cv::Mat Downscale(const cv::Mat& image, const Camera& camera) {
  if (camera.width == image.cols && camera.height == image.rows) return image;
  cv::Mat small;
  cv::resize(image, small, cv::Size(camera.width, camera.height), 0, 0, cv::INTER_AREA);
  return small;
}

// Reads frames through an image list or a video and hands out undistorted,
// size-checked frames in the order of the dataset's views.
class DatasetFrameSource : public FrameSource {
 public:
  DatasetFrameSource(std::vector<DatasetView> views, fs::path images_dir, fs::path video_path)
      : views_(std::move(views)), images_dir_(std::move(images_dir)), video_path_(std::move(video_path)) {
    if (!video_path_.empty()) {
      inner_ = std::make_unique<VideoSource>(video_path_);
    } else {
      std::vector<std::string> names;
      std::vector<cv::Size> sizes;  // each image's header is checked against its camera before decoding
      for (const DatasetView& v : views_) {
        names.push_back(v.name);
        sizes.emplace_back(v.source_width, v.source_height);
      }
      auto folder = std::make_unique<ImageFolderSource>(images_dir_, std::move(names));
      folder->ExpectSizes(std::move(sizes));
      inner_ = std::move(folder);
    }
  }

  int NumFrames() const override { return static_cast<int>(views_.size()); }

  bool Next(Frame* frame) override {
    if (next_ >= NumFrames()) return false;
    if (!inner_->Next(frame))
      throw InputError(video_path_.string(), "video ended after " + std::to_string(next_) +
                                                 " frames, but there are " + std::to_string(NumFrames()) +
                                                 " poses");
    Finish(next_, frame);
    ++next_;
    return true;
  }

  Frame Read(int index) override {
    if (index < 0 || index >= NumFrames())
      throw InputError(Source().string(), "frame index " + std::to_string(index) + " out of range [0, " +
                                              std::to_string(NumFrames()) + ")");
    Frame frame = inner_->Read(index);
    Finish(index, &frame);
    return frame;
  }

 private:
  fs::path Source() const { return video_path_.empty() ? images_dir_ : video_path_; }

  void Finish(int index, Frame* frame) {
    const DatasetView& view = views_[index];
    const Camera& camera = view.camera;
    if (frame->image.cols != view.source_width || frame->image.rows != view.source_height) {
      const std::string file =
          video_path_.empty() ? (images_dir_ / view.name).string() : video_path_.string();
      const std::string field = video_path_.empty() ? "" : "frame " + std::to_string(index);
      throw InputError(file, field,
                       "image is " + std::to_string(frame->image.cols) + "x" +
                           std::to_string(frame->image.rows) + " but its camera (" + view.name + ") is " +
                           std::to_string(view.source_width) + "x" + std::to_string(view.source_height));
    }
    frame->index = index;
    frame->name = view.name;
    frame->image = UndistorterFor(camera).Apply(Downscale(frame->image, camera));
  }

  const Undistorter& UndistorterFor(const Camera& camera) {
    for (const auto& [cam, undistorter] : undistorters_)
      if (cam == camera) return *undistorter;
    undistorters_.emplace_back(camera, std::make_unique<Undistorter>(camera));
    return *undistorters_.back().second;
  }

  std::vector<DatasetView> views_;
  fs::path images_dir_;
  fs::path video_path_;
  std::unique_ptr<FrameSource> inner_;
  std::vector<std::pair<Camera, std::unique_ptr<Undistorter>>> undistorters_;
  int next_ = 0;
};

struct PoseEntry {
  std::string name;
  Camera camera;
  Rigid3d cam_from_world;
  fs::path mask_path;  // Nerfstudio mask_path, resolved; empty: none
};

// Nerfstudio-style split files, in this order, when a folder has no transforms.json.
const char* const kTransformsSplits[] = {"transforms_train.json", "transforms_val.json", "transforms_test.json"};

// The size of an image file from its header (ImageFileHeaderSize), never by
// decoding it; nullopt when it cannot be opened. InputError naming the file
// when its format's header gives no size, or one beyond an int.
std::optional<std::pair<int, int>> ImageFileSize(const fs::path& path) {
  if (!std::ifstream(path, std::ios::binary)) return std::nullopt;
  const auto [width, height] = ImageFileHeaderSize(path);
  if (width > std::numeric_limits<int>::max() || height > std::numeric_limits<int>::max())
    throw InputError(path.string(), "image header says " + std::to_string(width) + "x" + std::to_string(height));
  return std::make_pair(static_cast<int>(width), static_cast<int>(height));
}

// PNG with an alpha channel (IHDR colour type 4 or 6).
bool PngHasAlpha(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  char b[26] = {};
  if (!in.read(b, sizeof(b))) return false;
  if (std::string(b + 1, 3) != "PNG" || std::string(b + 12, 4) != "IHDR") return false;
  return b[25] == 4 || b[25] == 6;
}

// A mask file for image `name` in `dir`: NAME.png (COLMAP's convention), STEM.png, NAME.
fs::path FindMaskFile(const fs::path& dir, const std::string& name) {
  fs::path with_png = dir / name;
  with_png += ".png";
  const fs::path stem_png = (dir / name).replace_extension(".png");
  for (const fs::path& p : {with_png, stem_png, dir / name})
    if (IsFile(p)) return p;
  return {};
}

}  // namespace

cv::Mat PrepareFrame(const cv::Mat& image, const Camera& camera) {
  const cv::Mat scaled = Downscale(image, camera);
  return camera.HasDistortion() ? Undistorter(camera).Apply(scaled) : scaled;
}

void DatasetOptions::Check() const {
  if (!images_dir.empty() && !video_path.empty())
    throw OptionError("give either an image folder (--images) or a video (--video), not both");
  if (!colmap_dir.empty() && !transforms_path.empty())
    throw OptionError("give either a COLMAP model (--colmap) or a transforms.json (--transforms), not both");
  if (dataset_dir.empty()) {
    if (images_dir.empty() && video_path.empty())
      throw OptionError("no input: give a dataset folder, or --images/--video with --colmap/--transforms");
    if (colmap_dir.empty() && transforms_path.empty())
      throw OptionError(
          "no poses: give --colmap or --transforms with --images/--video (or a dataset folder)");
  }
  if (bbox && !bbox->IsValid()) throw OptionError("--bbox: min must be finite and below max on every axis");
  if (max_image_size < 0) throw OptionError("--max-image-size must be positive (0: frames as stored)");
}

std::pair<int, int> ScaledImageSize(int width, int height, int max_size) {
  const int longer = std::max(width, height);
  if (max_size <= 0 || longer <= max_size) return {width, height};
  const double s = static_cast<double>(max_size) / longer;
  return {std::max(1, static_cast<int>(std::lround(width * s))), std::max(1, static_cast<int>(std::lround(height * s)))};
}

Dataset Dataset::Open(const DatasetOptions& options) {
  options.Check();
  Dataset ds;
  const fs::path& root = options.dataset_dir;
  if (!root.empty()) {
    if (!IsDir(root)) throw InputError(root.string(), "dataset folder does not exist");
    ds.root_ = root;
  }

  // Where the poses come from: explicit, else COLMAP in the dataset folder, else its transforms.json.
  fs::path model_dir, transforms_path = options.transforms_path;
  std::vector<fs::path> split_files;  // Nerfstudio splits, all read (transforms_path is the first)
  if (!options.colmap_dir.empty()) {
    if (!IsDir(options.colmap_dir))
      throw InputError(options.colmap_dir.string(), "COLMAP model folder does not exist");
    model_dir = FindColmapModel(options.colmap_dir);
    if (model_dir.empty())
      throw InputError(options.colmap_dir.string(),
                       "no COLMAP model (cameras + images, .txt or .bin) here, in sparse/ or in sparse/0/");
  } else if (!transforms_path.empty()) {
    if (!IsFile(transforms_path))
      throw InputError(transforms_path.string(), "transforms file does not exist");
  } else {
    model_dir = FindColmapModel(root);
    if (model_dir.empty()) {
      if (IsFile(root / "transforms.json")) {
        transforms_path = root / "transforms.json";
      } else {
        for (const char* split : kTransformsSplits)
          if (IsFile(root / split)) split_files.push_back(root / split);
        if (split_files.empty())
          throw InputError(root.string(),
                           "no poses: expected a COLMAP model in sparse/ or sparse/0/, transforms.json, or "
                           "Nerfstudio split files (transforms_train.json, transforms_val.json, transforms_test.json)");
        transforms_path = split_files.front();
      }
    } else if (IsFile(root / "transforms.json")) {
      spdlog::info("{}: using the COLMAP model in {}, not transforms.json", root.string(),
                   model_dir.string());
    }
  }

  // Where the frames come from: --video, --images, else the dataset's images/ (for a
  // transforms.json without images/, NeRF-synthetic style, its file_paths from the dataset folder).
  if (!options.video_path.empty()) {
    if (!IsFile(options.video_path))
      throw InputError(options.video_path.string(), "video file does not exist");
    ds.video_path_ = options.video_path;
  } else if (!options.images_dir.empty()) {
    ds.images_dir_ = options.images_dir;
  } else if (model_dir.empty() && !IsDir(root / "images")) {
    ds.images_dir_ = root;
  } else {
    ds.images_dir_ = root / "images";
  }
  if (ds.video_path_.empty() && !IsDir(ds.images_dir_))
    throw InputError(ds.images_dir_.string(), "image folder does not exist");

  std::vector<PoseEntry> entries;
  std::string pose_file;  // for messages
  if (!model_dir.empty()) {
    const bool binary = IsColmapModelBinary(model_dir);
    ds.pose_source_ = binary ? "colmap-binary" : "colmap-text";
    pose_file = (model_dir / (binary ? "images.bin" : "images.txt")).string();
    const ColmapModel model = ReadColmapModel(model_dir);
    for (const ColmapImage& image : model.images)
      entries.push_back({image.name, model.cameras.at(image.camera_id), image.cam_from_world, {}});
  } else {
    ds.pose_source_ = split_files.size() > 1 ? "transforms splits" : transforms_path.filename().string();
    if (split_files.empty()) split_files.push_back(transforms_path);
    std::optional<std::pair<int, int>> video_size;
    for (const fs::path& file : split_files) {
      pose_file = file.string();
      const fs::path base = file.parent_path();
      // Files without w/h: each image's own size (the video's for a video).
      const TransformsImageSize image_size = [&](const std::string& file_path) -> std::optional<std::pair<int, int>> {
        if (!ds.video_path_.empty()) {
          if (!video_size) {
            VideoSource video(ds.video_path_);
            Frame f;
            if (video.Next(&f)) video_size = std::make_pair(f.image.cols, f.image.rows);
          }
          return video_size;
        }
        const std::string name = ResolveTransformsImage(file_path, base, ds.images_dir_);
        if (name.empty()) return std::nullopt;
        return ImageFileSize(ds.images_dir_ / name);
      };
      const std::vector<TransformsFrame> frames = ReadTransformsJson(file, image_size);
      for (size_t i = 0; i < frames.size(); ++i) {
        std::string name = frames[i].file_path;
        if (ds.video_path_.empty()) {
          name = ResolveTransformsImage(frames[i].file_path, base, ds.images_dir_);
          if (name.empty())
            throw InputError(pose_file, "frames[" + std::to_string(i) + "].file_path",
                             InputToken(frames[i].file_path) + " matches no image in " + ds.images_dir_.string());
        }
        PoseEntry e{name, frames[i].camera, frames[i].cam_from_world, {}};
        if (!frames[i].mask_path.empty()) {
          // Like image names, a mask path stays below the transforms file's folder.
          const fs::path mp = fs::path(frames[i].mask_path).lexically_normal();
          bool escapes = mp.is_absolute() || mp.has_root_name() || mp.has_root_directory();
          for (const fs::path& part : mp) escapes = escapes || part == "..";
          if (escapes)
            throw InputError(pose_file, "frames[" + std::to_string(i) + "].mask_path",
                             InputToken(frames[i].mask_path) + " leaves the dataset folder (absolute or '..')");
          e.mask_path = base / mp;
          if (!IsFile(e.mask_path))
            throw InputError(pose_file, "frames[" + std::to_string(i) + "].mask_path",
                             InputToken(frames[i].mask_path) + " does not exist");
        }
        entries.push_back(std::move(e));
      }
    }
    if (split_files.size() > 1) {
      pose_file = root.string() + "/transforms_*.json";
      // The same image in two splits with the same pose is one view.
      std::sort(entries.begin(), entries.end(),
                [](const PoseEntry& a, const PoseEntry& b) { return NaturalNameLess(a.name, b.name); });
      entries.erase(std::unique(entries.begin(), entries.end(),
                                [](const PoseEntry& a, const PoseEntry& b) {
                                  return a.name == b.name && a.camera == b.camera &&
                                         a.cam_from_world.ToMatrix() == b.cam_from_world.ToMatrix();
                                }),
                    entries.end());
      spdlog::info("{}: {} views from {} split files", root.string(), entries.size(), split_files.size());
    }
  }
  if (entries.empty()) throw InputError(pose_file, "no poses in the file");

  std::sort(entries.begin(), entries.end(),
            [](const PoseEntry& a, const PoseEntry& b) { return NaturalNameLess(a.name, b.name); });
  for (size_t i = 1; i < entries.size(); ++i)
    if (entries[i].name == entries[i - 1].name)
      throw InputError(pose_file, InputToken(entries[i].name) + " has two poses");

  // An image name is a path *inside* the image folder: absolute names and
  // ".." components would let a pose file point the reader anywhere.
  for (const PoseEntry& e : entries) {
    const fs::path n(e.name);
    bool escapes = n.is_absolute() || n.has_root_name() || n.has_root_directory();
    for (const fs::path& part : n) escapes = escapes || part == "..";
    if (escapes)
      throw InputError(pose_file, "image name " + InputToken(e.name) + " leaves the image folder (absolute or '..')");
  }

  if (ds.video_path_.empty()) {
    // Every pose needs its image; images without a pose are left out (COLMAP
    // often fails to register a few frames), with a warning.
    std::set<std::string> posed;
    for (const PoseEntry& e : entries) {
      if (!IsFile(ds.images_dir_ / e.name))
        throw InputError((ds.images_dir_ / e.name).string(),
                         "image listed in " + pose_file + " does not exist");
      posed.insert(e.name);
    }
    const auto all = ImageFolderSource::FromFolder(ds.images_dir_);
    std::vector<std::string> unposed;
    for (const std::string& n : all->names())
      if (!posed.count(n)) unposed.push_back(n);
    if (!unposed.empty())
      spdlog::warn("{}: {} images have no pose and are skipped (first: {})", ds.images_dir_.string(),
                   unposed.size(), InputToken(unposed.front()));
  } else {
    // A video has no names: view k is frame k, so every frame needs a pose.
    VideoSource video(ds.video_path_);
    if (video.NumFrames() > 0 && video.NumFrames() != static_cast<int>(entries.size()))
      throw InputError(ds.video_path_.string(), "video has " + std::to_string(video.NumFrames()) +
                                                    " frames but " + pose_file + " gives " +
                                                    std::to_string(entries.size()) +
                                                    " poses; with a video, frame k takes the k-th pose in "
                                                    "name order, so the counts must agree");
  }

  // Masks: Nerfstudio's mask_path, else a mask folder, else the images' alpha channel.
  fs::path masks_dir = options.masks_dir;
  if (!masks_dir.empty() && !IsDir(masks_dir)) throw InputError(masks_dir.string(), "mask folder does not exist");
  if (masks_dir.empty() && !root.empty() && IsDir(root / "masks")) masks_dir = root / "masks";
  bool any_mask_path = false;
  for (const PoseEntry& e : entries) any_mask_path = any_mask_path || !e.mask_path.empty();
  if (any_mask_path) {
    ds.mask_source_ = "mask_path";
  } else if (!masks_dir.empty()) {
    int found = 0;
    for (PoseEntry& e : entries) {
      e.mask_path = FindMaskFile(masks_dir, e.name);
      found += !e.mask_path.empty();
    }
    if (found > 0) {
      ds.mask_source_ = "masks/";
      if (found < static_cast<int>(entries.size()))
        spdlog::warn("{}: masks for {} of {} views", masks_dir.string(), found, entries.size());
    } else {
      spdlog::warn("{}: no mask matches an image name (NAME.png, STEM.png or NAME)", masks_dir.string());
    }
  } else if (ds.video_path_.empty() && PngHasAlpha(ds.images_dir_ / entries.front().name)) {
    ds.mask_source_ = "alpha";
  }

  for (size_t i = 0; i < entries.size(); ++i) {
    DatasetView v;
    v.index = static_cast<int>(i);
    v.name = std::move(entries[i].name);
    v.source_width = entries[i].camera.width;
    v.source_height = entries[i].camera.height;
    const auto [w, h] = ScaledImageSize(v.source_width, v.source_height, options.max_image_size);
    v.camera = entries[i].camera.Scaled(w, h);
    v.cam_from_world = entries[i].cam_from_world;
    v.mask_path = std::move(entries[i].mask_path);
    ds.views_.push_back(std::move(v));
  }
  if (options.max_image_size > 0 && ds.views_.front().camera.width != ds.views_.front().source_width)
    spdlog::info("frames read at {}x{} (stored {}x{}; --max-image-size {})", ds.views_.front().camera.width,
                 ds.views_.front().camera.height, ds.views_.front().source_width, ds.views_.front().source_height,
                 options.max_image_size);

  // The foreground volume V.
  if (options.bbox) {
    ds.bbox_ = *options.bbox;
    ds.bbox_source_ = "--bbox";
  } else {
    bool from_scene = false;
    if (!root.empty() && IsFile(root / "scene.json")) {
      const json scene = ReadJsonFile(root / "scene.json");
      // A scene.json without the keys is not an error: V is then estimated.
      if (scene.is_object() &&
          (scene.contains("foreground_bbox_min") || scene.contains("foreground_bbox_max"))) {
        ds.bbox_ = ReadSceneJsonBoundingBox(root / "scene.json");
        from_scene = true;
      } else if (!scene.is_object()) {
        throw InputError((root / "scene.json").string(), "not a valid JSON object");
      }
    }
    if (from_scene) {
      ds.bbox_source_ = "scene.json";
    } else {
      ds.bbox_ = EstimateBoundingBox(ds.views_);
      ds.bbox_source_ = "estimated";
      if (ds.HasMasks()) {
        // The visual hull of up to 32 masked views spread over the sequence, searched
        // in a cube around the cameras' look-at point reaching the cameras.
        std::vector<PinholeView> views;
        std::vector<cv::Mat> masks;
        const int n = ds.NumViews(), take = std::min(n, 32);
        for (int k = 0; k < take; ++k) {
          const int i = static_cast<int>(static_cast<long long>(k) * n / take);
          views.push_back(ds.View(i));
          masks.push_back(ds.ReadMask(i));
        }
        double distance = 0;
        for (const PinholeView& v : views) distance = std::max(distance, (v.Center() - ds.bbox_.Center()).norm());
        BoundingBox search;
        search.min = ds.bbox_.Center() - Eigen::Vector3d::Constant(distance);
        search.max = ds.bbox_.Center() + Eigen::Vector3d::Constant(distance);
        if (auto box = BoundingBoxFromMasks(views, masks, search)) {
          ds.bbox_ = *box;
          ds.bbox_source_ = "masks (" + ds.mask_source_ + ")";
        } else {
          spdlog::warn("the masks' visual hull is empty (masks inverted, or poses wrong?); V estimated from the cameras");
        }
      }
    }
  }
  spdlog::info("{}: {} views, poses from {}, V from {}: [{:.3f} {:.3f} {:.3f}] - [{:.3f} {:.3f} {:.3f}]",
               root.empty() ? (ds.video_path_.empty() ? ds.images_dir_.string() : ds.video_path_.string())
                            : root.string(),
               ds.views_.size(), ds.pose_source_, ds.bbox_source_, ds.bbox_.min.x(), ds.bbox_.min.y(),
               ds.bbox_.min.z(), ds.bbox_.max.x(), ds.bbox_.max.y(), ds.bbox_.max.z());
  return ds;
}

cv::Mat Dataset::ReadMask(int i) const {
  const DatasetView& v = views_.at(i);
  cv::Mat raw;
  std::string file;
  if (!v.mask_path.empty()) {
    file = v.mask_path.string();
    // Its size from its header before it is decoded (any format, image_header.h).
    const auto [hw, hh] = ImageFileHeaderSize(v.mask_path);
    if (hw != v.source_width || hh != v.source_height)
      throw InputError(file, "mask header is " + std::to_string(hw) + "x" + std::to_string(hh) + " but its image is " +
                                 std::to_string(v.source_width) + "x" + std::to_string(v.source_height));
    // IMREAD_IGNORE_ORIENTATION as for the frames (COLMAP ignores EXIF orientation).
    raw = cv::imread(file, cv::IMREAD_GRAYSCALE | cv::IMREAD_IGNORE_ORIENTATION);
    if (raw.empty()) throw InputError(file, "mask cannot be read");
  } else if (mask_source_ == "alpha") {
    file = ImagePath(i).string();
    const auto [hw, hh] = ImageFileHeaderSize(ImagePath(i));  // checked before it is decoded again
    if (hw != v.source_width || hh != v.source_height)
      throw InputError(file, "image header is " + std::to_string(hw) + "x" + std::to_string(hh) + ", was " +
                                 std::to_string(v.source_width) + "x" + std::to_string(v.source_height));
    const cv::Mat image = cv::imread(file, cv::IMREAD_UNCHANGED);
    if (image.empty()) throw InputError(file, "image cannot be read");
    if (image.channels() != 4 && image.channels() != 2) return cv::Mat();
    cv::extractChannel(image, raw, image.channels() - 1);
    if (raw.depth() != CV_8U) raw.convertTo(raw, CV_8U, 255.0 / 65535.0);
  } else {
    return cv::Mat();
  }
  if (raw.cols != v.source_width || raw.rows != v.source_height)
    throw InputError(file, "mask is " + std::to_string(raw.cols) + "x" + std::to_string(raw.rows) +
                               " but its image (" + v.name + ") is " + std::to_string(v.source_width) + "x" +
                               std::to_string(v.source_height));
  cv::Mat m = raw;
  if (v.camera.width != raw.cols || v.camera.height != raw.rows)
    cv::resize(raw, m, cv::Size(v.camera.width, v.camera.height), 0, 0, cv::INTER_AREA);
  if (v.camera.HasDistortion()) m = Undistorter(v.camera).Apply(m);
  cv::Mat out;
  cv::threshold(m, out, 127, 255, cv::THRESH_BINARY);
  return out;
}

fs::path Dataset::ImagePath(int i) const {
  if (images_dir_.empty()) return {};
  return images_dir_ / views_.at(i).name;
}

Camera Dataset::UndistortedCamera(int i) const {
  // As Undistorter does (same focal lengths and principal point), without building its maps.
  const Camera& c = views_.at(i).camera;
  return Camera::Pinhole(c.width, c.height, c.fx(), c.fy(), c.cx(), c.cy());
}

PinholeView Dataset::View(int i) const {
  return PinholeView(UndistortedCamera(i), views_.at(i).cam_from_world);
}

std::unique_ptr<FrameSource> Dataset::OpenFrames() const {
  return std::make_unique<DatasetFrameSource>(views_, images_dir_, video_path_);
}

std::optional<fs::path> Dataset::GroundTruthDepthPath(int i) const {
  if (root_.empty() || i < 0) return std::nullopt;
  char name[32];
  std::snprintf(name, sizeof(name), "depth_%04d.exr", i);
  const fs::path p = root_ / "depth" / name;
  if (!IsFile(p)) return std::nullopt;
  return p;
}

std::optional<fs::path> Dataset::GroundTruthMeshPath(bool thin_only) const {
  if (root_.empty()) return std::nullopt;
  const fs::path p = root_ / (thin_only ? "gt_thin.ply" : "gt_mesh.ply");
  if (!IsFile(p)) return std::nullopt;
  return p;
}

BoundingBox ReadSceneJsonBoundingBox(const fs::path& path) {
  const std::string file = path.string();
  const json scene = ReadJsonFile(path);
  auto vec = [&](const char* key) {
    if (!scene.is_object() || !scene.contains(key)) throw InputError(file, key, "missing");
    const json& a = scene[key];
    if (!a.is_array() || a.size() != 3) throw InputError(file, key, "must be an array of 3 numbers");
    Eigen::Vector3d v;
    for (int k = 0; k < 3; ++k) {
      if (!a[k].is_number()) throw InputError(file, key, "must be an array of 3 numbers");
      v[k] = a[k].get<double>();
    }
    return v;
  };
  BoundingBox box;
  box.min = vec("foreground_bbox_min");
  box.max = vec("foreground_bbox_max");
  if (!box.IsValid())
    throw InputError(file, "foreground_bbox_min/max", "min must be finite and below max on every axis");
  return box;
}

BoundingBox EstimateBoundingBox(const std::vector<DatasetView>& views) {
  if (views.empty()) throw std::invalid_argument("EstimateBoundingBox needs at least one view");
  // Least-squares point nearest to all optical axes: sum_i (I - d_i d_i^T)(p - c_i) = 0.
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  Eigen::Vector3d mean_center = Eigen::Vector3d::Zero(), mean_dir = Eigen::Vector3d::Zero();
  for (const DatasetView& v : views) {
    const Eigen::Vector3d c = CameraCenter(v.cam_from_world);
    const Eigen::Vector3d d = ViewingDirection(v.cam_from_world);
    const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - d * d.transpose();
    A += P;
    b += P * c;
    mean_center += c;
    mean_dir += d;
  }
  const double n = static_cast<double>(views.size());
  mean_center /= n;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(A / n);
  Eigen::Vector3d center;
  if (eig.eigenvalues().minCoeff() > 1e-4) {
    center = A.ldlt().solve(b);
  } else {
    // Axes (nearly) parallel: no common look-at point; take one unit ahead of the mean camera.
    spdlog::warn("EstimateBoundingBox: the cameras' optical axes are nearly parallel; V is a guess");
    center = mean_center + (mean_dir.norm() > 0 ? mean_dir.normalized() : Eigen::Vector3d::UnitZ());
  }
  std::vector<double> distances, half_fovs;
  for (const DatasetView& v : views) {
    distances.push_back((center - CameraCenter(v.cam_from_world)).dot(ViewingDirection(v.cam_from_world)));
    const Camera& c = v.camera;
    half_fovs.push_back(std::min(std::atan(0.5 * c.width / c.fx()), std::atan(0.5 * c.height / c.fy())));
  }
  auto median = [](std::vector<double> x) {
    std::nth_element(x.begin(), x.begin() + x.size() / 2, x.end());
    return x[x.size() / 2];
  };
  double distance = median(distances);
  if (!(distance > 0)) distance = (center - mean_center).norm();
  if (!(distance > 0)) distance = 1.0;
  // The cube seen whole by a camera at the median distance with the narrower field of view.
  const double half = distance * std::tan(median(half_fovs));
  BoundingBox box;
  box.min = center - Eigen::Vector3d::Constant(half);
  box.max = center + Eigen::Vector3d::Constant(half);
  return box;
}

namespace {

// Grid search of the visual hull's bounds inside `box`, `n` cells a side.
std::optional<BoundingBox> HullBounds(const std::vector<PinholeView>& views, const std::vector<cv::Mat>& masks,
                                      const BoundingBox& box, int n) {
  int masked = 0;
  for (const cv::Mat& m : masks) masked += !m.empty();
  const Eigen::Vector3d cell = box.Extent() / n;
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity());
  Eigen::Vector3d hi = -lo;
  bool any = false;
  for (int z = 0; z < n; ++z)
    for (int y = 0; y < n; ++y)
      for (int x = 0; x < n; ++x) {
        const Eigen::Vector3d p = box.min + cell.cwiseProduct(Eigen::Vector3d(x + 0.5, y + 0.5, z + 0.5));
        int seen = 0;
        bool inside = true;
        for (size_t k = 0; k < views.size() && inside; ++k) {
          if (masks[k].empty()) continue;
          Eigen::Vector2d px;
          if (views[k].Project(p, &px) <= 0 || !views[k].InImage(px)) continue;
          ++seen;
          inside = masks[k].at<std::uint8_t>(static_cast<int>(px.y()), static_cast<int>(px.x())) != 0;
        }
        if (!inside || 2 * seen < masked) continue;
        lo = lo.cwiseMin(p);
        hi = hi.cwiseMax(p);
        any = true;
      }
  if (!any) return std::nullopt;
  BoundingBox out;
  out.min = lo - cell;
  out.max = hi + cell;
  return out;
}

}  // namespace

std::optional<BoundingBox> BoundingBoxFromMasks(const std::vector<PinholeView>& views,
                                                const std::vector<cv::Mat>& masks, const BoundingBox& search) {
  if (views.size() != masks.size()) throw std::invalid_argument("BoundingBoxFromMasks: one mask per view");
  auto coarse = HullBounds(views, masks, search, 96);
  if (!coarse) return std::nullopt;
  auto fine = HullBounds(views, masks, *coarse, 96);
  BoundingBox box = fine ? *fine : *coarse;
  const Eigen::Vector3d margin = 0.05 * box.Extent();
  box.min -= margin;
  box.max += margin;
  return box;
}

}  // namespace lfrecon
