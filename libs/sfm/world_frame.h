#pragma once
// The world frame of an SfM reconstruction, which has no up, no origin and no
// metric scale: up from the cameras' mean up vector (or the normal of a planar camera path), the foreground volume V
// from the robust extent of the sparse points the cameras look at, and a
// similarity that puts up on +z, the origin at V's bottom centre and the
// cameras at a nominal median distance from V's centre. Also the similarity
// alignment (Umeyama) of estimated cameras to reference ones and their errors.
#include <Eigen/Core>
#include <filesystem>
#include <vector>

#include "geometry/camera.h"
#include "geometry/rigid3.h"
#include "geometry/triangle_mesh.h"

namespace lfrecon {

// x' = scale * rotation * x + translation.
struct Similarity3d {
  double scale = 1;
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Eigen::Vector3d operator*(const Eigen::Vector3d& x) const { return scale * (rotation * x) + translation; }
  // The cam_from_world pose of the same camera in the transformed world (its
  // camera frame scaled by `scale` too, so its images are unchanged).
  Rigid3d TransformPose(const Rigid3d& cam_from_world) const;
  Similarity3d Inverse() const;
};

// A point of a COLMAP points3D file: position, mean reprojection error (px)
// and the images that see it (image ids).
struct SparsePoint {
  Eigen::Vector3d xyz = Eigen::Vector3d::Zero();
  double error = 0;
  std::vector<std::uint32_t> image_ids;
};

// Reads points3D.bin or points3D.txt from a COLMAP model folder (binary first).
// Throws InputError naming the file and the point on malformed input.
std::vector<SparsePoint> ReadColmapPoints3D(const std::filesystem::path& model_dir);

struct WorldFrameOptions {
  double camera_distance = 1.0;   // median camera distance from V's centre after scaling (nominal metres)
  int min_track_length = 3;       // sparse points seen by fewer images are ignored
  double max_error_px = 2.0;      // ... and points with a larger mean reprojection error
  double central_fraction = 0.8;  // "looked at": projects into the central part of an image (this fraction of W and H)
  double min_view_fraction = 0.7; // ... in at least this fraction of the views (in front of them)
  // V spans these percentiles of the kept points per axis (its top at least
  // up to where the views' upper image edge meets the vertical axis through
  // V's centre: thin and tall things have few points) ...
  double percentile = 0.02;
  double padding = 0.1;           // ... grown by this fraction of its extent on each side
  int max_views = 300;            // views used for the "looked at" test (evenly spread)
  // Up: the cameras' mean up, or the normal of the camera centres' plane when
  // they lie near one (eigenvalues of their scatter l0 <= l1 <= l2:
  // l1 > planar_min_spread * l2 and l0 < planar_max_thickness * l1) within
  // planar_max_tilt_deg of the mean up.
  double planar_min_spread = 0.05;
  double planar_max_thickness = 0.01;
  double planar_max_tilt_deg = 45;

  void Check() const;
};

struct WorldFrame {
  Similarity3d sfm_to_world;         // SfM coordinates -> the normalised world
  BoundingBox volume;                // V in the normalised world
  Eigen::Vector3d up_sfm = Eigen::Vector3d::UnitZ();  // the cameras' mean up in SfM coordinates
  double up_spread_deg = 0;          // mean angle of the cameras' up vectors from it
  bool up_from_path = false;         // up is the normal of the camera path's plane (else the mean up)
  int points_total = 0;              // sparse points after the track/error filter
  int points_in_volume = 0;          // of them, the ones the cameras look at
};

// `cam_from_world` and `cameras` in SfM coordinates, one camera per view.
// Throws InputError(source, ...) when there are too few views or points.
WorldFrame EstimateWorldFrame(const std::vector<Rigid3d>& cam_from_world, const std::vector<Camera>& cameras,
                              const std::vector<SparsePoint>& points, const WorldFrameOptions& options,
                              const std::string& source = "sparse model");

// The similarity mapping the camera centres of `estimated` onto those of
// `reference` in the least-squares sense (Umeyama, with scale). Needs >= 3
// views with centres not all on one line.
Similarity3d AlignCameras(const std::vector<Rigid3d>& estimated, const std::vector<Rigid3d>& reference);

struct PoseErrors {
  int views = 0;
  double median_rotation_deg = 0, max_rotation_deg = 0;
  double median_center = 0, max_center = 0;  // in the reference's units
  double camera_distance = 0;               // median distance of the reference centres from `reference_point`
  double median_center_relative() const { return camera_distance > 0 ? median_center / camera_distance : 0; }
  double max_center_relative() const { return camera_distance > 0 ? max_center / camera_distance : 0; }
};

// Errors of `estimated` mapped by `estimated_to_reference` against `reference`.
PoseErrors ComparePoses(const std::vector<Rigid3d>& estimated, const std::vector<Rigid3d>& reference,
                        const Similarity3d& estimated_to_reference, const Eigen::Vector3d& reference_point);

}  // namespace lfrecon
