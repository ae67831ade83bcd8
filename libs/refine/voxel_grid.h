#pragma once
// A sparse voxel grid of the fused surface for the refinement stage (BRIEF
// §1.6, paper §5 end): per voxel a state (occupied, free or unknown) and the
// surface probability H it came from. Carving turns occupied voxels free;
// meshing follows the H = threshold iso-surface of what is left.
//
// It is a copy of the fusion grid's active voxels (ProbabilisticFusion keeps
// its OpenVDB tree to itself and is read-only once fused), stored in 8³
// blocks so memory follows the surface like the fusion grid does.
#include <Eigen/Core>
#include <cstdint>
#include <functional>
#include <memory>
#include <unordered_map>
#include <vector>

#include "geometry/triangle_mesh.h"

namespace lfrecon {

// The six face neighbours of a voxel (used by the voxel grid and carving).
inline const Eigen::Vector3i kSixNeighbours[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0},
                                                  {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};

class ProbabilisticFusion;

enum class VoxelState : std::uint8_t {
  kUnknown = 0,   // not observed (not active in the fusion grid, e.g. deep inside the object)
  kFree = 1,      // observed, H < threshold, or carved
  kOccupied = 2,  // observed, H >= threshold
};

class VoxelGrid {
 public:
  // Voxel (i, j, k) has its centre at volume.min + (i + ½, j + ½, k + ½) · voxel_size,
  // as in ProbabilisticFusion.
  VoxelGrid(const BoundingBox& volume, double voxel_size, double threshold);

  // The fused grid: every active voxel with evidence from at least
  // `min_views` views is occupied when H >= `threshold`, free otherwise;
  // voxels without evidence stay unknown.
  static VoxelGrid FromFusion(const ProbabilisticFusion& fusion, double threshold, int min_views = 1);

  const BoundingBox& volume() const { return volume_; }
  double voxel_size() const { return voxel_size_; }
  double threshold() const { return threshold_; }

  VoxelState State(const Eigen::Vector3i& ijk) const;
  // H of a known voxel (0 for carved and unknown ones).
  float Value(const Eigen::Vector3i& ijk) const;
  void Set(const Eigen::Vector3i& ijk, VoxelState state, float value);
  // Marks an occupied voxel free with H = 0, so the iso-surface moves past it.
  void Carve(const Eigen::Vector3i& ijk) { Set(ijk, VoxelState::kFree, 0.0f); }

  Eigen::Vector3d Center(const Eigen::Vector3i& ijk) const;
  Eigen::Vector3i Index(const Eigen::Vector3d& world) const;

  std::size_t CountOccupied() const;
  std::vector<Eigen::Vector3i> OccupiedVoxels() const;  // deterministic order
  // Occupied with a free 6-neighbour: on the outer surface. (Occupied voxels
  // next to unknown ones border the unobserved inside, not free space.)
  bool IsExposed(const Eigen::Vector3i& ijk) const;

  // Marching cubes of H at the threshold over cells whose 8 corners are known
  // (as ProbabilisticFusion::ExtractMesh: no wall towards the unobserved
  // inside); outward vertex normals.
  TriangleMesh ExtractMesh() const;

 private:
  struct Block {
    float value[512];
    VoxelState state[512];
  };
  static std::uint64_t BlockKey(const Eigen::Vector3i& block);
  const Block* FindBlock(const Eigen::Vector3i& ijk, int* offset) const;

  BoundingBox volume_;
  double voxel_size_;
  double threshold_;
  std::unordered_map<std::uint64_t, std::unique_ptr<Block>> blocks_;
};

}  // namespace lfrecon
