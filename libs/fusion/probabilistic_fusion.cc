#include "fusion/probabilistic_fusion.h"

#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>
#include <openvdb/tools/Morphology.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tree/ValueAccessor.h>
#include <spdlog/spdlog.h>
#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <mutex>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <utility>
#include <vector>


#include "fusion/marching_cubes_table.h"
#include "fusion/surface_evidence.h"
#include "util/error.h"
#include "util/progress.h"

namespace lfrecon {
namespace {

using EvidenceTree = openvdb::Vec2STree;  // (Σ log P_i, number of views) per voxel
using EvidenceLeaf = EvidenceTree::LeafNodeType;
using MaskLeaf = openvdb::MaskTree::LeafNodeType;
using openvdb::Coord;
using openvdb::Vec2s;
// SurfaceEvidence::BlockLogProbability evaluates one leaf: 8^3 voxels, voxel n = 64 x + 8 y + z,
// its active bit n % 64 of mask word n / 64.
static_assert(EvidenceLeaf::DIM == SurfaceEvidence::kBlockDim && MaskLeaf::DIM == SurfaceEvidence::kBlockDim);
static_assert(EvidenceLeaf::NodeMaskType::WORD_COUNT == SurfaceEvidence::kBlockDim);

void InitOpenVdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

// static_cast<int>(std::floor(x)) for |x| < 2^31, without floor(): the
// build targets baseline x86-64, where floor is a long instruction sequence
// (no SSE4.1 roundsd).
inline int FloorToInt(double x) {
  const int t = static_cast<int>(x);  // towards zero
  return t - (x < t);
}

Coord CornerOffset(int k) { return Coord(k & 1, (k >> 1) & 1, (k >> 2) & 1); }

// 21 + 21 + 20 bits of voxel index (all >= 0, < 2^20) and 2 bits of axis.
std::uint64_t EdgeKey(const Coord& c, int axis) {
  return (static_cast<std::uint64_t>(c.x()) << 43) | (static_cast<std::uint64_t>(c.y()) << 22) |
         (static_cast<std::uint64_t>(c.z()) << 2) | static_cast<std::uint64_t>(axis);
}

}  // namespace

void MeshingOptions::Check() const {
  LFRECON_CHECK_OPTION(threshold < 0 || (threshold > 0 && threshold < 1));
  LFRECON_CHECK_OPTION(min_views >= 1);
}

struct ProbabilisticFusion::Impl {
  FusionOptions options;
  EvidenceTree tree{Vec2s(0.0f, 0.0f)};
  std::vector<std::unique_ptr<CompactDepthView>> views;
  std::unordered_set<int> view_ids;
  Eigen::Vector3i dims;
  FusionStats stats;

  Eigen::Vector3d Center(const Coord& c) const {
    return options.volume.min + options.voxel_size * (Eigen::Vector3d(c.x(), c.y(), c.z()).array() + 0.5).matrix();
  }

  openvdb::MaskTree Activate(const CompactDepthView& cv) const;
  void BackFill(const openvdb::MaskTree& fresh, std::size_t num_previous);
  void Apply(const SurfaceEvidence& evidence);
  SurfaceEvidence::BlockCentres BlockCentres(const Coord& origin) const;  // of a leaf's voxels
  // values[n] += (lp[n], 1) for each voxel n of a leaf whose bit is set in `has`.
  static void AddEvidence(Vec2s* values, const float* lp, const std::uint64_t* has);
  void EnforceBudget();
  bool warned_budget = false;
};

void ProbabilisticFusion::Impl::EnforceBudget() {
  const std::size_t budget = options.store_budget_bytes;
  if (budget == 0) return;
  while (stats.store_bytes > budget) {
    // The oldest of the finest views.
    std::size_t best = views.size();
    for (std::size_t i = 0; i < views.size(); ++i)
      if (views[i]->block() < options.store_max_block && (best == views.size() || views[i]->block() < views[best]->block()))
        best = i;
    if (best == views.size()) {
      if (!warned_budget)
        spdlog::warn("fusion: the depth store ({:.0f} MiB) exceeds its budget ({:.0f} MiB) with every view at {}x{} "
                     "blocks; it keeps growing",
                     stats.store_bytes / 1048576.0, budget / 1048576.0, options.store_max_block,
                     options.store_max_block);
      warned_budget = true;
      return;
    }
    CompactDepthView& v = *views[best];
    const std::size_t before = v.MemoryBytes();
    if (v.block() == 1) ++stats.store_coarsened_views;
    v = v.Coarsened(options.BandHalfWidth());
    stats.store_bytes = stats.store_bytes - before + v.MemoryBytes();
    stats.store_max_block = std::max(stats.store_max_block, v.block());
  }
}

openvdb::MaskTree ProbabilisticFusion::Impl::Activate(const CompactDepthView& cv) const {
  const PinholeView& view = cv.view();
  const double s = options.voxel_size;
  const double band = options.BandHalfWidth();
  const double step = 0.5 * s;                         // along the ray
  const double lateral = options.activation_step * s;  // between sub-pixel rays
  const double f = std::min(view.K(0, 0), view.K(1, 1));
  const Eigen::Matrix3d ray_from_pixel = view.R.transpose() * view.K_inv;  // world offset per unit planar depth
  const Eigen::Vector3d center = view.Center();
  const Eigen::Vector3d vmin = options.volume.min;
  const int nx = dims.x(), ny = dims.y(), nz = dims.z();

  tbb::enumerable_thread_specific<openvdb::MaskTree> locals;
  tbb::parallel_for(tbb::blocked_range<int>(0, view.height), [&](const tbb::blocked_range<int>& rows) {
    openvdb::MaskTree& local = locals.local();
    openvdb::tree::ValueAccessor<openvdb::MaskTree> acc(local);
    for (int r = rows.begin(); r < rows.end(); ++r) {
      for (int c = 0; c < view.width; ++c) {
        const CompactDepthView::Pixel& p = cv.at(r, c);
        if (p.depth == 0 || CompactDepthView::Label(p) != DepthLabel::kForeground) continue;
        if (CompactDepthView::Confidence(p) < options.activation_min_confidence) continue;
        const double d = cv.Depth(p);
        // Sub-pixel rays so that neighbouring rays are at most `lateral` apart at depth d.
        const int k = std::clamp(static_cast<int>(std::ceil(d / f / lateral)), 1, 16);
        const double z0 = std::max(d - band, 1e-6), z1 = d + band;
        for (int b = 0; b < k; ++b) {
          for (int a = 0; a < k; ++a) {
            const Eigen::Vector3d w = ray_from_pixel * Eigen::Vector3d(c + (a + 0.5) / k, r + (b + 0.5) / k, 1.0);
            const int n = std::max(1, static_cast<int>(std::ceil((z1 - z0) * w.norm() / step)));
            Coord last(-1, -1, -1);
            for (int m = 0; m <= n; ++m) {
              const double z = z0 + (z1 - z0) * m / n;
              const Eigen::Vector3d g = (center + z * w - vmin) / s;
              const Coord ijk(FloorToInt(g.x()), FloorToInt(g.y()), FloorToInt(g.z()));
              if (ijk == last) continue;
              last = ijk;
              if (ijk.x() < 0 || ijk.y() < 0 || ijk.z() < 0 || ijk.x() >= nx || ijk.y() >= ny || ijk.z() >= nz) continue;
              acc.setValueOn(ijk);
            }
          }
        }
      }
    }
  });
  openvdb::MaskTree out;
  for (openvdb::MaskTree& t : locals) out.topologyUnion(t);
  return out;
}

void ProbabilisticFusion::Impl::BackFill(const openvdb::MaskTree& fresh, std::size_t num_previous) {
  std::vector<const MaskLeaf*> mask_leaves;
  fresh.getNodes(mask_leaves);
  std::vector<SurfaceEvidence> evidence;
  evidence.reserve(num_previous);
  evidence.emplace_back(*views[0], options);
  for (std::size_t i = 1; i < num_previous; ++i) evidence.emplace_back(*views[i], evidence.front());  // tables shared
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, mask_leaves.size()), [&](const auto& range) {
    std::uint64_t active[SurfaceEvidence::kBlockDim], has[SurfaceEvidence::kBlockDim];
    float lp[SurfaceEvidence::kBlockVoxels];
    for (std::size_t li = range.begin(); li < range.end(); ++li) {
      const MaskLeaf& mask = *mask_leaves[li];
      EvidenceLeaf* leaf = tree.probeLeaf(mask.origin());
      if (!leaf) continue;  // cannot happen: fresh was merged into the tree
      const SurfaceEvidence::BlockCentres centres = BlockCentres(mask.origin());
      for (int w = 0; w < SurfaceEvidence::kBlockDim; ++w) active[w] = mask.getValueMask().getWord<std::uint64_t>(w);
      Vec2s* values = leaf->buffer().data();
      // View by view, so each voxel still sums its views' log P in the order of the store.
      for (const SurfaceEvidence& ev : evidence) {
        ev.BlockLogProbability(centres, active, lp, has);
        AddEvidence(values, lp, has);
      }
    }
  });
}

SurfaceEvidence::BlockCentres ProbabilisticFusion::Impl::BlockCentres(const Coord& origin) const {
  SurfaceEvidence::BlockCentres b;
  for (int t = 0; t < SurfaceEvidence::kBlockDim; ++t) {
    b.x[t] = Center(origin.offsetBy(t, 0, 0)).x();
    b.y[t] = Center(origin.offsetBy(0, t, 0)).y();
    b.z[t] = Center(origin.offsetBy(0, 0, t)).z();
  }
  return b;
}

void ProbabilisticFusion::Impl::AddEvidence(Vec2s* values, const float* lp, const std::uint64_t* has) {
  for (int i = 0; i < SurfaceEvidence::kBlockDim; ++i)
    for (std::uint64_t w = has[i]; w; w &= w - 1) {
      const int n = i * 64 + __builtin_ctzll(w);
      values[n] = Vec2s(values[n][0] + lp[n], values[n][1] + 1.0f);
    }
}

void ProbabilisticFusion::Impl::Apply(const SurfaceEvidence& evidence) {
  std::vector<EvidenceLeaf*> leaves;
  tree.getNodes(leaves);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size()), [&](const auto& range) {
    std::uint64_t active[SurfaceEvidence::kBlockDim], has[SurfaceEvidence::kBlockDim];
    float lp[SurfaceEvidence::kBlockVoxels];
    for (std::size_t li = range.begin(); li < range.end(); ++li) {
      EvidenceLeaf& leaf = *leaves[li];
      for (int w = 0; w < SurfaceEvidence::kBlockDim; ++w) active[w] = leaf.getValueMask().getWord<std::uint64_t>(w);
      evidence.BlockLogProbability(BlockCentres(leaf.origin()), active, lp, has);
      AddEvidence(leaf.buffer().data(), lp, has);
    }
  });
}

ProbabilisticFusion::ProbabilisticFusion(const FusionOptions& options) : impl_(std::make_unique<Impl>()) {
  options.Check();
  InitOpenVdb();
  impl_->options = options;
  impl_->dims = options.GridSize();
}

ProbabilisticFusion::~ProbabilisticFusion() = default;
ProbabilisticFusion::ProbabilisticFusion(ProbabilisticFusion&&) noexcept = default;
ProbabilisticFusion& ProbabilisticFusion::operator=(ProbabilisticFusion&&) noexcept = default;

const FusionOptions& ProbabilisticFusion::options() const { return impl_->options; }
int ProbabilisticFusion::NumViews() const { return static_cast<int>(impl_->views.size()); }

bool ProbabilisticFusion::HasView(int view_id) const { return impl_->view_ids.count(view_id) > 0; }

bool ProbabilisticFusion::Integrate(const PinholeView& view, const DepthMap& input, int view_id) {
  if (view_id >= 0 && HasView(view_id)) {
    spdlog::warn("fusion: view {} was already integrated; ignored", view_id);
    return false;
  }
  if (input.depth.empty() || input.depth.rows != view.height || input.depth.cols != view.width)
    throw std::invalid_argument("fusion: depth map is " + std::to_string(input.depth.cols) + "x" +
                                std::to_string(input.depth.rows) + ", its view " + std::to_string(view.width) + "x" +
                                std::to_string(view.height));
  Impl& m = *impl_;
  const DepthMap& depth = input;
  auto compact = std::make_unique<CompactDepthView>(view, depth, m.options.volume);

  Timer timer;
  openvdb::MaskTree fresh = m.Activate(*compact);
  fresh.topologyDifference(m.tree);
  m.tree.topologyUnion(fresh);
  const std::size_t num_fresh = fresh.activeVoxelCount();
  m.stats.activate_s += timer.Seconds();

  timer.Restart();
  if (num_fresh > 0 && !m.views.empty()) m.BackFill(fresh, m.views.size());
  m.stats.backfill_s += timer.Seconds();

  timer.Restart();
  m.Apply(SurfaceEvidence(*compact, m.options));
  m.stats.update_s += timer.Seconds();

  m.stats.store_bytes += compact->MemoryBytes();
  m.views.push_back(std::move(compact));
  timer.Restart();
  m.EnforceBudget();
  m.stats.coarsen_s += timer.Seconds();
  m.stats.views = static_cast<int>(m.views.size());
  if (view_id >= 0) m.view_ids.insert(view_id);
  if (m.options.prune_every > 0 && m.views.size() % m.options.prune_every == 0) Prune();
  spdlog::debug("fusion: view {} integrated: {} new voxels, {} active", m.views.size(), num_fresh,
                m.tree.activeVoxelCount());
  return true;
}

std::size_t ProbabilisticFusion::Prune() {
  Impl& m = *impl_;
  Timer timer;
  // Keep every voxel at or above prune_below and its 26 neighbours.
  const float log_keep = static_cast<float>(std::log(m.options.prune_below));
  openvdb::MaskTree keep;
  {
    openvdb::tree::ValueAccessor<openvdb::MaskTree> acc(keep);
    for (auto it = m.tree.cbeginValueOn(); it; ++it) {
      if (!it.isVoxelValue()) continue;
      const Vec2s v = *it;
      if (v[1] > 0 && v[0] >= log_keep * v[1]) acc.setValueOn(it.getCoord());
    }
  }
  openvdb::tools::dilateActiveValues(keep, 1, openvdb::tools::NN_FACE_EDGE_VERTEX, openvdb::tools::IGNORE_TILES);
  std::vector<EvidenceLeaf*> leaves;
  m.tree.getNodes(leaves);
  std::vector<std::size_t> dropped(leaves.size(), 0);
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size()), [&](const auto& range) {
    for (std::size_t li = range.begin(); li < range.end(); ++li) {
      EvidenceLeaf& leaf = *leaves[li];
      const MaskLeaf* k = keep.probeConstLeaf(leaf.origin());
      for (auto it = leaf.beginValueOn(); it; ++it) {
        if (k && k->isValueOn(it.pos())) continue;
        // Back to the background value, so a re-activation back-fills from zero.
        leaf.setValueOff(it.pos(), Vec2s(0.0f, 0.0f));
        ++dropped[li];
      }
    }
  });
  openvdb::tools::pruneInactive(m.tree);
  std::size_t n = 0;
  for (std::size_t d : dropped) n += d;
  m.stats.pruned_voxels += n;
  m.stats.prune_s += timer.Seconds();
  spdlog::debug("fusion: pruned {} voxels, {} active", n, m.tree.activeVoxelCount());
  return n;
}

FusionStats ProbabilisticFusion::Stats() const {
  FusionStats s = impl_->stats;
  s.active_voxels = impl_->tree.activeVoxelCount();
  s.grid_bytes = impl_->tree.memUsage();
  return s;
}

Eigen::Vector3d ProbabilisticFusion::VoxelCenter(const Eigen::Vector3i& ijk) const {
  return impl_->Center(Coord(ijk.x(), ijk.y(), ijk.z()));
}

Eigen::Vector3i ProbabilisticFusion::VoxelIndex(const Eigen::Vector3d& world) const {
  const Eigen::Vector3d g = (world - impl_->options.volume.min) / impl_->options.voxel_size;
  return g.array().floor().cast<int>();
}

double ProbabilisticFusion::SurfaceProbability(const Eigen::Vector3i& ijk, int* num_views) const {
  Vec2s v;
  const bool on = impl_->tree.probeValue(Coord(ijk.x(), ijk.y(), ijk.z()), v);
  const int n = on ? static_cast<int>(v[1]) : 0;
  if (num_views) *num_views = n;
  return n > 0 ? std::exp(static_cast<double>(v[0]) / n) : 0.0;
}

bool ProbabilisticFusion::IsActive(const Eigen::Vector3i& ijk) const {
  return impl_->tree.isValueOn(Coord(ijk.x(), ijk.y(), ijk.z()));
}

void ProbabilisticFusion::ForEachVoxel(
    const std::function<void(const Eigen::Vector3i& ijk, double sum_log_p, int num_views)>& f) const {
  for (auto it = impl_->tree.cbeginValueOn(); it; ++it) {
    if (!it.isVoxelValue()) continue;
    const Coord c = it.getCoord();
    const Vec2s v = *it;
    f(Eigen::Vector3i(c.x(), c.y(), c.z()), v[0], static_cast<int>(v[1]));
  }
}

TriangleMesh ProbabilisticFusion::ExtractMesh(const MeshingOptions& mo) const {
  mo.Check();
  const Impl& m = *impl_;
  const float iso = static_cast<float>(mo.threshold < 0 ? m.options.surface_threshold : mo.threshold);
  const float min_views = static_cast<float>(mo.min_views);
  const double s = m.options.voxel_size;
  const auto& edges = mc::Edges();

  std::vector<const EvidenceLeaf*> leaves;
  m.tree.getNodes(leaves);
  struct LeafMesh {
    std::vector<std::pair<std::uint64_t, Eigen::Vector3f>> vertices;
    std::vector<std::array<std::uint64_t, 3>> triangles;
  };
  std::vector<LeafMesh> parts(leaves.size());
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size()), [&](const auto& range) {
    openvdb::tree::ValueAccessor<const EvidenceTree> acc(m.tree);
    for (std::size_t li = range.begin(); li < range.end(); ++li) {
      LeafMesh& out = parts[li];
      for (auto it = leaves[li]->cbeginValueOn(); it; ++it) {
        const Coord ijk = it.getCoord();
        float h[8];
        int mask = 0;
        bool complete = true;
        for (int k = 0; k < 8 && complete; ++k) {
          Vec2s v;
          if (!acc.probeValue(ijk + CornerOffset(k), v) || v[1] < min_views) {
            complete = false;
            break;
          }
          h[k] = std::exp(v[0] / v[1]);
          if (h[k] >= iso) mask |= 1 << k;
        }
        if (!complete || mask == 0 || mask == 255) continue;
        std::array<std::uint64_t, 12> keys{};
        std::array<bool, 12> done{};
        for (const auto& tri : mc::Triangles(mask)) {
          std::array<std::uint64_t, 3> t;
          for (int q = 0; q < 3; ++q) {
            const int e = tri[q];
            if (!done[e]) {
              const mc::Edge& edge = edges[e];
              const Coord c0 = ijk + CornerOffset(edge.corner0);
              const float h0 = h[edge.corner0], h1 = h[edge.corner1];
              const double frac = std::clamp(static_cast<double>((iso - h0) / (h1 - h0)), 0.0, 1.0);
              Eigen::Vector3d p = m.Center(c0);
              p[edge.axis] += frac * s;
              keys[e] = EdgeKey(c0, edge.axis);
              out.vertices.emplace_back(keys[e], p.cast<float>());
              done[e] = true;
            }
            t[q] = keys[e];
          }
          out.triangles.push_back(t);
        }
      }
    }
  });

  TriangleMesh mesh;
  std::unordered_map<std::uint64_t, int> index;
  std::size_t num_tris = 0;
  for (const LeafMesh& p : parts) num_tris += p.triangles.size();
  index.reserve(num_tris);
  mesh.triangles.reserve(num_tris);
  for (const LeafMesh& p : parts) {
    for (const auto& [key, pos] : p.vertices) {
      if (index.emplace(key, static_cast<int>(mesh.vertices.size())).second) mesh.vertices.push_back(pos);
    }
    for (const auto& t : p.triangles) mesh.triangles.emplace_back(index.at(t[0]), index.at(t[1]), index.at(t[2]));
  }
  mesh.ComputeVertexNormals();
  return mesh;
}

void ProbabilisticFusion::WriteVdb(const std::filesystem::path& path) const {
  const Impl& m = *impl_;
  const double s = m.options.voxel_size;
  openvdb::math::Transform::Ptr xf = openvdb::math::Transform::createLinearTransform(s);
  const Eigen::Vector3d o = m.options.volume.min + Eigen::Vector3d::Constant(0.5 * s);
  xf->postTranslate(openvdb::Vec3d(o.x(), o.y(), o.z()));
  auto make = [&](const std::string& name) {
    openvdb::FloatGrid::Ptr g = openvdb::FloatGrid::create(0.0f);
    g->setName(name);
    g->setTransform(xf->copy());
    g->setGridClass(openvdb::GRID_FOG_VOLUME);
    return g;
  };
  openvdb::FloatGrid::Ptr h = make("surface_probability"), sum = make("log_p_sum"), count = make("view_count");
  {
    auto ha = h->getAccessor(), sa = sum->getAccessor(), ca = count->getAccessor();
    for (auto it = m.tree.cbeginValueOn(); it; ++it) {
      if (!it.isVoxelValue()) continue;
      const Coord c = it.getCoord();
      const Vec2s v = *it;
      ha.setValue(c, v[1] > 0 ? std::exp(v[0] / v[1]) : 0.0f);
      sa.setValue(c, v[0]);
      ca.setValue(c, v[1]);
    }
  }
  h->insertMeta("surface_threshold", openvdb::FloatMetadata(static_cast<float>(m.options.surface_threshold)));
  h->insertMeta("views", openvdb::Int32Metadata(static_cast<int>(m.views.size())));
  h->insertMeta("sigma_v_voxels", openvdb::FloatMetadata(static_cast<float>(m.options.sigma_v)));
  h->insertMeta("sigma_s", openvdb::FloatMetadata(static_cast<float>(m.options.sigma_s)));
  try {
    openvdb::io::File file(path.string());
    file.write({h, sum, count});
    file.close();
  } catch (const openvdb::Exception& e) {
    throw std::runtime_error("cannot write " + path.string() + ": " + e.what());
  }
}

}  // namespace lfrecon
