#pragma once
// A light-field dataset: an ordered sequence of views (image name, camera,
// pose), a lazily read stream of their frames, and the foreground volume V.
//
// Dataset::Open accepts either a folder laid out like ../shared/data/figurines
// (images/ + sparse/ or sparse/0/ (COLMAP text or binary) or transforms.json,
// optional scene.json, depth/, gt_mesh.ply, gt_thin.ply), or explicit sources
// (--images or --video, with --colmap or --transforms). Nerfstudio-style
// split files (transforms_train.json, transforms_val.json, transforms_test.json)
// are read when the folder has no transforms.json: every split present, merged.
// V comes from --bbox, else scene.json, else the masks' visual hull when there
// are masks, else is estimated from where the cameras look.
// Masks (foreground 255, CV_8U): a frame's Nerfstudio mask_path, else
// masks/NAME.png, masks/STEM.png or masks/NAME (COLMAP's and Nerfstudio's
// layouts), else the image's alpha channel (PNG with alpha).
// With max_image_size, frames are downscaled on read (cv::INTER_AREA) so that
// their longer side is at most that many pixels; cameras are scaled with them.
// Problems throw InputError naming the file and field.
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "geometry/camera.h"
#include "geometry/pinhole_view.h"
#include "geometry/rigid3.h"
#include "geometry/triangle_mesh.h"
#include "io/frame_source.h"

namespace lfrecon {

struct DatasetOptions {
  std::filesystem::path dataset_dir;      // auto-detected layout
  std::filesystem::path images_dir;       // explicit image folder
  std::filesystem::path video_path;       // explicit video file
  std::filesystem::path colmap_dir;       // explicit COLMAP model folder (or its parent)
  std::filesystem::path transforms_path;  // explicit transforms.json
  std::optional<BoundingBox> bbox;        // explicit V (world, metres)
  std::filesystem::path masks_dir;        // explicit mask folder (default: the dataset's masks/ when present)
  int max_image_size = 0;                 // > 0: downscale frames so that their longer side is at most this

  // Throws OptionError if the combination is not usable.
  void Check() const;
};

struct DatasetView {
  int index = 0;     // position in the sequence (0-based)
  std::string name;  // image name relative to the image folder
  Camera camera;     // as given (may have distortion), scaled to the frames as read (max_image_size)
  Rigid3d cam_from_world;
  int source_width = 0, source_height = 0;  // the stored frame's size (camera's before scaling)
  std::filesystem::path mask_path;          // the view's mask file; empty: none (or the alpha channel)
};

// The longer side at most `max_size` (0: unchanged): the size frames are read at.
// Each side is rounded to the nearest pixel, at least 1.
std::pair<int, int> ScaledImageSize(int width, int height, int max_size);

// A frame decoded at its stored size -> as Dataset::OpenFrames hands it out:
// downscaled to `camera`'s size when it differs (cv::INTER_AREA, as the camera
// was scaled) and undistorted (Undistorter of `camera`; none without
// distortion). The job store decodes its frames through this too, so the
// service sees the pixels `lfrecon run` sees.
cv::Mat PrepareFrame(const cv::Mat& image, const Camera& camera);

class Dataset {
 public:
  static Dataset Open(const DatasetOptions& options);

  const std::vector<DatasetView>& views() const { return views_; }
  int NumViews() const { return static_cast<int>(views_.size()); }
  const BoundingBox& bbox() const { return bbox_; }
  const std::string& bbox_source() const { return bbox_source_; }  // "--bbox", "scene.json" or "estimated"
  const std::string& pose_source() const { return pose_source_; }  // "colmap-text", "colmap-binary", "transforms.json"
  // Where masks come from: "mask_path", "masks/" (a folder), "alpha", or "" (none).
  const std::string& mask_source() const { return mask_source_; }
  bool HasMasks() const { return !mask_source_.empty(); }
  // The mask of view i as its frames are read (scaled, undistorted): CV_8U, 255
  // on the object, 0 elsewhere; an empty Mat when view i has none.
  cv::Mat ReadMask(int i) const;
  const std::filesystem::path& root() const { return root_; }      // dataset folder (empty for explicit sources)
  const std::filesystem::path& images_dir() const { return images_dir_; }  // empty when frames come from a video
  const std::filesystem::path& video_path() const { return video_path_; }  // empty when frames come from images
  // The image file of view i (empty path for video input).
  std::filesystem::path ImagePath(int i) const;

  // The distortion-free camera of view i after ingest, and its geometry.
  Camera UndistortedCamera(int i) const;
  PinholeView View(int i) const;

  // Frames in the order of views(), undistorted, each checked against its
  // camera's size (InputError naming the file otherwise).
  std::unique_ptr<FrameSource> OpenFrames() const;

  // Ground truth shipped with a dataset (figurines and the synthetic generator):
  // depth/depth_NNNN.exr for sequence index NNNN, gt_mesh.ply, gt_thin.ply.
  std::optional<std::filesystem::path> GroundTruthDepthPath(int i) const;
  std::optional<std::filesystem::path> GroundTruthMeshPath(bool thin_only = false) const;

 private:
  std::vector<DatasetView> views_;
  BoundingBox bbox_;
  std::string bbox_source_;
  std::string pose_source_;
  std::string mask_source_;
  std::filesystem::path root_;
  std::filesystem::path images_dir_;
  std::filesystem::path video_path_;
};

// V from scene.json's foreground_bbox_min/max; throws InputError if absent or malformed.
BoundingBox ReadSceneJsonBoundingBox(const std::filesystem::path& path);
// V estimated from the cameras: a cube around the point closest (least
// squares) to all optical axes, sized from the median viewing distance and
// the field of view.
BoundingBox EstimateBoundingBox(const std::vector<DatasetView>& views);
// V from foreground masks (CV_8U, 255 on the object; an empty Mat: no mask for
// that view) of undistorted views: the bounds of the visual hull, searched in
// `search` on a grid (a second, finer grid over the first result), grown by a
// cell and 5 %. A point is kept if it projects onto the object in every masked
// view that sees it and is seen by at least half of them. nullopt when nothing is kept.
std::optional<BoundingBox> BoundingBoxFromMasks(const std::vector<PinholeView>& views,
                                                const std::vector<cv::Mat>& masks, const BoundingBox& search);

}  // namespace lfrecon
