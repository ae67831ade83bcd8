#include "pipeline/reconstruction_plan.h"

#include <algorithm>
#include <cmath>

#include "geometry/view_graph.h"
#include "util/error.h"

namespace lfrecon {

void ViewSelectionOptions::Check() const {
  LFRECON_CHECK_OPTION(min_step_deg >= 0 && min_step_deg < 90);
}

std::vector<int> SelectViews(const std::vector<PinholeView>& views, const ViewSelectionOptions& o) {
  std::vector<int> out;
  const int n = static_cast<int>(views.size());
  if (!o.enabled || !(o.min_step_deg > 0)) {
    for (int i = 0; i < n; ++i) out.push_back(i);
    return out;
  }
  const std::vector<char> kept = SpacedAtLeast(ViewingDirections(views), o.min_step_deg);
  for (int k = 0; k < n; ++k)
    if (kept[static_cast<std::size_t>(k)]) out.push_back(k);
  return out;
}

std::vector<int> EvenlySpread(const std::vector<int>& views, int k) {
  std::vector<int> out;
  k = std::min<int>(k, static_cast<int>(views.size()));
  for (int c = 0; c < k; ++c) out.push_back(views[static_cast<std::size_t>(c) * views.size() / k]);
  return out;
}

ReconstructionPlan ReconstructionPlan::Compute(const std::vector<PinholeView>& cameras, const BoundingBox& volume,
                                               const PipelineOptions& options) {
  options.Check();
  const int n = static_cast<int>(cameras.size());
  if (n == 0) throw OptionError("reconstruction plan: no views");
  ReconstructionPlan plan;
  plan.fusion = PipelineFusionOptions(options, volume);
  std::vector<int> wanted = options.views.empty() ? SelectViews(cameras, options.selection) : options.views;
  // Selected views are the filter's voters (StreamingDepthOptions::voter_min_step_deg):
  // the same greedy rule at the same step, so no view but the selected ones needs a sparse map.
  StreamingDepthOptions depth = options.depth;
  if (options.views.empty() && options.selection.enabled &&
      options.selection.min_step_deg < depth.filter.max_view_angle_deg)
    depth.voter_min_step_deg = std::max(depth.voter_min_step_deg, options.selection.min_step_deg);
  plan.depth = PlanDepth(cameras, depth, wanted);  // checks the range, sorts
  plan.views = plan.depth.wanted;
  plan.emit_frame = EmitFrames(plan.depth);
  plan.order = plan.views;
  std::stable_sort(plan.order.begin(), plan.order.end(), [&](int a, int b) {
    return plan.emit_frame[static_cast<std::size_t>(a)] < plan.emit_frame[static_cast<std::size_t>(b)];
  });
  plan.order_position.assign(static_cast<std::size_t>(n), -1);
  for (std::size_t k = 0; k < plan.order.size(); ++k)
    plan.order_position[static_cast<std::size_t>(plan.order[k])] = static_cast<int>(k);
  plan.selected.assign(static_cast<std::size_t>(n), 0);
  for (int i : plan.views) plan.selected[static_cast<std::size_t>(i)] = 1;
  plan.photo.assign(static_cast<std::size_t>(n), {});
  if (options.densify) {
    const ViewGraph photo(ViewingDirections(cameras), options.propagation.photo.max_view_angle_deg, options.depth.max_frame_gap);
    // Only the hierarchy grid's frames (on_grid: >= level_min_step_deg apart,
    // every frame of a sequence >= 0.5° apart) are photoconsistency
    // neighbours. On a dense sequence (0.12°: ~80 frames within 5°) each one
    // was expanded, smoothed and compared for every view it serves, and held
    // in the densification window until then; near-duplicates add little to
    // C± (docs/benchmarks.md, "Photoconsistency neighbours on the grid").
    for (int i : plan.views)
      for (int j : photo.Neighbors(i))
        if (plan.depth.on_grid[static_cast<std::size_t>(j)]) plan.photo[static_cast<std::size_t>(i)].push_back(j);
  }
  plan.color_frames = EvenlySpread(plan.views, options.color_views);
  if (options.refine && options.refine_options.carve)
    plan.carving_frames = EvenlySpread(plan.views, options.carving_views);
  return plan;
}

int ReconstructionPlan::FinalOrder(bool ended, const PipelineOptions& options) const {
  if (ended) return static_cast<int>(order.size());
  // A view of frame >= settled is emitted at a frame >= settled.
  const int settled = SettledFrames(num_views(), false, options);
  int k = 0;
  while (k < static_cast<int>(order.size()) && emit_frame[static_cast<std::size_t>(order[k])] < settled) ++k;
  return k;
}

int ReconstructionPlan::SettledFrames(int received, bool ended, const PipelineOptions& options) {
  if (received <= 0) return 0;
  if (ended) return received;
  const long long gap = options.depth.max_frame_gap;
  if (gap <= 0 || !options.views.empty()) return 0;
  return static_cast<int>(std::max<long long>(0, received - 2 * gap));
}

int ReconstructionPlan::SettledDepthFrames(int received, bool ended, const PipelineOptions& options) {
  if (received <= 0) return 0;
  if (ended) return received;
  const long long gap = options.depth.max_frame_gap;
  if (gap <= 0 || !options.views.empty()) return 0;
  return static_cast<int>(std::max<long long>(0, received - gap));
}

}  // namespace lfrecon
