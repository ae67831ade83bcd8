#include "refine/voxel_grid.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

#include "fusion/marching_cubes_table.h"
#include "fusion/probabilistic_fusion.h"

namespace lfrecon {
namespace {

constexpr int kBias = 1 << 20;  // block coordinates are stored as 21-bit unsigned fields

Eigen::Vector3i BlockOf(const Eigen::Vector3i& ijk) { return {ijk.x() >> 3, ijk.y() >> 3, ijk.z() >> 3}; }
int OffsetIn(const Eigen::Vector3i& ijk) { return (ijk.x() & 7) | ((ijk.y() & 7) << 3) | ((ijk.z() & 7) << 6); }

Eigen::Vector3i DecodeBlock(std::uint64_t key) {
  const auto f = [&](int shift) { return static_cast<int>((key >> shift) & ((1u << 21) - 1)) - kBias; };
  return {f(0), f(21), f(42)};
}

Eigen::Vector3i CornerOffset(int k) { return {k & 1, (k >> 1) & 1, (k >> 2) & 1}; }

// Marching-cubes vertex on the edge from voxel c0 along `axis`; 20 bits per
// axis cover grids far larger than any V we mesh (fusion allows 2^20 voxels
// per axis, but such a grid would not fit in memory anyway).
std::uint64_t EdgeKey(const Eigen::Vector3i& c0, int axis) {
  const auto u = [](int v) { return static_cast<std::uint64_t>(v + 1) & 0xFFFFFull; };
  return u(c0.x()) | (u(c0.y()) << 20) | (u(c0.z()) << 40) | (static_cast<std::uint64_t>(axis) << 60);
}

}  // namespace

VoxelGrid::VoxelGrid(const BoundingBox& volume, double voxel_size, double threshold)
    : volume_(volume), voxel_size_(voxel_size), threshold_(threshold) {
  if (!volume.IsValid() || !(voxel_size > 0) || !(threshold > 0 && threshold < 1))
    throw std::invalid_argument("VoxelGrid: needs a valid volume, voxel_size > 0 and a threshold in (0, 1)");
}

VoxelGrid VoxelGrid::FromFusion(const ProbabilisticFusion& fusion, double threshold, int min_views) {
  VoxelGrid grid(fusion.options().volume, fusion.options().voxel_size, threshold);
  fusion.ForEachVoxel([&](const Eigen::Vector3i& ijk, double sum_log_p, int n) {
    if (n < std::max(1, min_views)) return;
    const double h = std::exp(sum_log_p / n);
    grid.Set(ijk, h >= threshold ? VoxelState::kOccupied : VoxelState::kFree, static_cast<float>(h));
  });
  return grid;
}

std::uint64_t VoxelGrid::BlockKey(const Eigen::Vector3i& b) {
  const auto u = [](int v) { return static_cast<std::uint64_t>(v + kBias) & ((1u << 21) - 1); };
  return u(b.x()) | (u(b.y()) << 21) | (u(b.z()) << 42);
}

const VoxelGrid::Block* VoxelGrid::FindBlock(const Eigen::Vector3i& ijk, int* offset) const {
  const auto it = blocks_.find(BlockKey(BlockOf(ijk)));
  if (it == blocks_.end()) return nullptr;
  *offset = OffsetIn(ijk);
  return it->second.get();
}

VoxelState VoxelGrid::State(const Eigen::Vector3i& ijk) const {
  int o;
  const Block* b = FindBlock(ijk, &o);
  return b ? b->state[o] : VoxelState::kUnknown;
}

float VoxelGrid::Value(const Eigen::Vector3i& ijk) const {
  int o;
  const Block* b = FindBlock(ijk, &o);
  return b ? b->value[o] : 0.0f;
}

void VoxelGrid::Set(const Eigen::Vector3i& ijk, VoxelState state, float value) {
  auto& slot = blocks_[BlockKey(BlockOf(ijk))];
  if (!slot) {
    slot = std::make_unique<Block>();
    std::fill(std::begin(slot->value), std::end(slot->value), 0.0f);
    std::fill(std::begin(slot->state), std::end(slot->state), VoxelState::kUnknown);
  }
  const int o = OffsetIn(ijk);
  slot->state[o] = state;
  slot->value[o] = value;
}

Eigen::Vector3d VoxelGrid::Center(const Eigen::Vector3i& ijk) const {
  return volume_.min + (ijk.cast<double>().array() + 0.5).matrix() * voxel_size_;
}

Eigen::Vector3i VoxelGrid::Index(const Eigen::Vector3d& world) const {
  const Eigen::Vector3d g = (world - volume_.min) / voxel_size_;
  return {static_cast<int>(std::floor(g.x())), static_cast<int>(std::floor(g.y())), static_cast<int>(std::floor(g.z()))};
}

std::size_t VoxelGrid::CountOccupied() const {
  std::size_t n = 0;
  for (const auto& [key, b] : blocks_)
    for (VoxelState s : b->state) n += s == VoxelState::kOccupied;
  return n;
}

std::vector<Eigen::Vector3i> VoxelGrid::OccupiedVoxels() const {
  std::vector<std::uint64_t> keys;
  keys.reserve(blocks_.size());
  for (const auto& kv : blocks_) keys.push_back(kv.first);
  std::sort(keys.begin(), keys.end());
  std::vector<Eigen::Vector3i> out;
  for (std::uint64_t key : keys) {
    const Block& b = *blocks_.at(key);
    const Eigen::Vector3i base = DecodeBlock(key) * 8;
    for (int o = 0; o < 512; ++o)
      if (b.state[o] == VoxelState::kOccupied) out.push_back(base + Eigen::Vector3i(o & 7, (o >> 3) & 7, o >> 6));
  }
  return out;
}

bool VoxelGrid::IsExposed(const Eigen::Vector3i& ijk) const {
  if (State(ijk) != VoxelState::kOccupied) return false;
  for (const Eigen::Vector3i& d : kSixNeighbours)
    if (State(ijk + d) == VoxelState::kFree) return true;
  return false;
}

TriangleMesh VoxelGrid::ExtractMesh() const {
  const float iso = static_cast<float>(threshold_);
  const auto& edges = mc::Edges();
  std::vector<std::uint64_t> keys;
  keys.reserve(blocks_.size());
  for (const auto& kv : blocks_) keys.push_back(kv.first);
  std::sort(keys.begin(), keys.end());  // deterministic vertex order
  struct Part {
    std::vector<std::pair<std::uint64_t, Eigen::Vector3f>> vertices;
    std::vector<std::array<std::uint64_t, 3>> triangles;
  };
  std::vector<Part> parts(keys.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, keys.size()), [&](const auto& range) {
    for (std::size_t bi = range.begin(); bi < range.end(); ++bi) {
      const Eigen::Vector3i base = DecodeBlock(keys[bi]) * 8;
      const Block& block = *blocks_.at(keys[bi]);
      Part& out = parts[bi];
      for (int o = 0; o < 512; ++o) {
        if (block.state[o] == VoxelState::kUnknown) continue;
        const Eigen::Vector3i ijk = base + Eigen::Vector3i(o & 7, (o >> 3) & 7, o >> 6);
        float h[8];
        int mask = 0;
        bool complete = true;
        for (int k = 0; k < 8; ++k) {
          const Eigen::Vector3i c = ijk + CornerOffset(k);
          int co;
          const Block* cb = k == 0 ? &block : FindBlock(c, &co);
          if (k == 0) co = o;
          if (!cb || cb->state[co] == VoxelState::kUnknown) {
            complete = false;
            break;
          }
          h[k] = cb->value[co];
          if (h[k] >= iso) mask |= 1 << k;
        }
        if (!complete || mask == 0 || mask == 255) continue;
        std::array<std::uint64_t, 12> ekeys{};
        std::array<bool, 12> done{};
        for (const auto& tri : mc::Triangles(mask)) {
          std::array<std::uint64_t, 3> t;
          for (int q = 0; q < 3; ++q) {
            const int e = tri[q];
            if (!done[e]) {
              const mc::Edge& edge = edges[e];
              const Eigen::Vector3i c0 = ijk + CornerOffset(edge.corner0);
              const float h0 = h[edge.corner0], h1 = h[edge.corner1];
              const double frac = std::clamp(static_cast<double>((iso - h0) / (h1 - h0)), 0.0, 1.0);
              Eigen::Vector3d p = Center(c0);
              p[edge.axis] += frac * voxel_size_;
              ekeys[e] = EdgeKey(c0, edge.axis);
              out.vertices.emplace_back(ekeys[e], p.cast<float>());
              done[e] = true;
            }
            t[q] = ekeys[e];
          }
          out.triangles.push_back(t);
        }
      }
    }
  });
  TriangleMesh mesh;
  std::unordered_map<std::uint64_t, int> index;
  for (const Part& p : parts) {
    for (const auto& [key, pos] : p.vertices)
      if (index.emplace(key, static_cast<int>(mesh.vertices.size())).second) mesh.vertices.push_back(pos);
    for (const auto& t : p.triangles) mesh.triangles.emplace_back(index.at(t[0]), index.at(t[1]), index.at(t[2]));
  }
  mesh.ComputeVertexNormals();
  return mesh;
}

}  // namespace lfrecon
