#pragma once
// Outputs that other tools open (issue 17):
// - meshes as PLY (our writer), OBJ or GLB (Open3D's io::WriteTriangleMesh),
//   chosen by extension;
// - a point cloud from per-view depth maps: every valid pixel back-projected,
//   kept inside V, thinned to one point per voxel (the centroid of its points,
//   as Open3D's VoxelDownSample, but accumulated view by view so that memory
//   is bounded by the occupied voxels, not by all pixels);
// - a COLMAP dense workspace of the processed views: images/ (undistorted
//   frames), sparse/ (PINHOLE cameras and poses, text), stereo/depth_maps/ and
//   stereo/normal_maps/ (NAME.geometric.bin, COLMAP's format, io/colmap_dense.h),
//   stereo/fusion.cfg and patch-match.cfg: `colmap stereo_fusion
//   --workspace_path DIR --input_type geometric` and OpenMVS's InterfaceCOLMAP read it.
#include <filesystem>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "geometry/pinhole_view.h"
#include "geometry/triangle_mesh.h"

namespace lfrecon {

// .ply, .obj, .glb or .gltf; throws InputError naming the file otherwise or on failure.
void WriteMeshFile(const TriangleMesh& mesh, const std::filesystem::path& path);

class PointCloudAccumulator {
 public:
  // voxel <= 0: every point kept.
  PointCloudAccumulator(const BoundingBox& volume, double voxel);
  ~PointCloudAccumulator();
  // `depth` (CV_32F planar depth, 0 or non-finite: none) of `view`, optional
  // `color` (CV_32FC3 BGR in [0, 1] or CV_8UC3, or empty).
  void Add(const PinholeView& view, const cv::Mat& depth, const cv::Mat& color = cv::Mat());
  // One point per occupied voxel (centroid), mean normal (facing the cameras), mean colour.
  TriangleMesh Result() const;

 private:
  struct Impl;
  Impl* impl_;
};

// PointCloudAccumulator over all views at once.
TriangleMesh PointCloudFromDepthMaps(const std::vector<PinholeView>& views, const std::vector<cv::Mat>& depth,
                                     const std::vector<cv::Mat>& colors, const BoundingBox& volume, double voxel);

// Normals of a planar depth map (CV_32FC3, camera coordinates, unit, facing the
// camera; 0 where a pixel or its 4-neighbours lack depth).
cv::Mat NormalsFromDepth(const PinholeView& view, const cv::Mat& depth);

struct ColmapWorkspaceView {
  std::string name;  // image name in the workspace (".png" appended unless it ends so)
  PinholeView view;
  cv::Mat image;     // undistorted frame, CV_32FC3 BGR [0, 1] or 8-bit
  cv::Mat depth;     // CV_32F planar depth, 0: none
};
// Writes a workspace view by view (images and maps at once; the model and the
// .cfg files at Finish, also called by the destructor if not yet).
class ColmapWorkspaceWriter {
 public:
  explicit ColmapWorkspaceWriter(std::filesystem::path dir);
  ~ColmapWorkspaceWriter();
  // Returns the image's name in the workspace.
  std::string Add(const ColmapWorkspaceView& view);
  void Finish();

 private:
  struct Impl;
  Impl* impl_;
};
// All views at once; returns the image names written.
std::vector<std::string> WriteColmapWorkspace(const std::filesystem::path& dir,
                                              const std::vector<ColmapWorkspaceView>& views);

}  // namespace lfrecon
