#include "depth/streaming_depth.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <map>
#include <set>

#include "depth/sliding_vote_grid.h"
#include "geometry/view_graph.h"
#include "util/error.h"
#include "util/progress.h"

namespace lfrecon {

void StreamingDepthOptions::Check() const {
  gradient.Check();
  filter.Check();
  LFRECON_CHECK_OPTION(max_frame_gap >= 0);
  LFRECON_CHECK_OPTION(voter_min_step_deg >= 0 && voter_min_step_deg < filter.max_view_angle_deg);
}

StreamingDepth::StreamingDepth(std::vector<PinholeView> views, const BoundingBox& volume,
                               const StreamingDepthOptions& options)
    : views_(std::move(views)), volume_(volume), options_(options) {
  options_.Check();
}

std::vector<int> FilterVoters(const ViewGraph& wide, const std::vector<char>& can_vote, int i) {
  std::vector<int> out;
  for (int j : wide.Neighbors(i))
    if (can_vote.at(static_cast<std::size_t>(j))) out.push_back(j);
  return out;
}

DepthPlan PlanDepth(const std::vector<PinholeView>& views, const StreamingDepthOptions& options,
                    std::vector<int> wanted) {
  const int n = static_cast<int>(views.size());
  if (wanted.empty())
    for (int i = 0; i < n; ++i) wanted.push_back(i);
  for (int i : wanted)
    if (i < 0 || i >= n) throw OptionError("view index " + std::to_string(i) + " out of range [0, " + std::to_string(n) + ")");
  std::sort(wanted.begin(), wanted.end());
  wanted.erase(std::unique(wanted.begin(), wanted.end()), wanted.end());
  DepthPlan plan;
  plan.wanted = wanted;
  const std::vector<Eigen::Vector3d> dirs = ViewingDirections(views);
  const ViewGraph near(dirs, options.gradient.max_view_angle_deg, options.max_frame_gap);
  // The frames each sparse map uses: the estimator's own selection among the
  // views within 5°, on the sequence's hierarchy grid (level_min_step_deg), so
  // a dense sequence holds only the grid frames and the pending references
  // with their nearest neighbours, not every frame within 5°. The filter's
  // voters lie on the same grid, or on a coarser one spaced voter_min_step_deg
  // (FilterVoters says why).
  plan.on_grid = HierarchyGrid(views, options.gradient);
  plan.voters.assign(n, {});
  if (options.run_filter) {
    const ViewGraph wide(dirs, options.filter.max_view_angle_deg, options.max_frame_gap);
    // At the voters' step: the same greedy spacing as the plan's view
    // selection (SpacedAtLeast), so the voters are the selected views.
    const double grid_step = options.gradient.use_hierarchy ? options.gradient.level_min_step_deg : 0.0;
    const std::vector<char> can_vote = options.voter_min_step_deg > 0
                                           ? SpacedAtLeast(dirs, std::max(grid_step, options.voter_min_step_deg))
                                           : plan.on_grid;
    for (int i : wanted) {
      plan.voters[i] = FilterVoters(wide, can_vote, i);
      std::sort(plan.voters[i].begin(), plan.voters[i].end());
    }
  }
  plan.need_sparse.assign(n, 0);
  for (int i : wanted) {
    plan.need_sparse[i] = 1;
    for (int j : plan.voters[i]) plan.need_sparse[j] = 1;
  }
  plan.uses.assign(n, {});
  for (int s = 0; s < n; ++s) {
    if (!plan.need_sparse[s]) continue;
    const std::vector<int>& nb = near.Neighbors(s);
    std::vector<const PinholeView*> nb_views;
    std::vector<char> nb_grid;
    for (int j : nb) {
      nb_views.push_back(&views[j]);
      nb_grid.push_back(plan.on_grid[j]);
    }
    for (int q : SelectHierarchyViews(views[s], nb_views, nb_grid, options.gradient)) plan.uses[s].push_back(nb[q]);
  }
  plan.read_before_emit.assign(n, -1);
  for (int i : wanted) {
    int last = i;
    for (int j : near.Neighbors(i)) last = std::max(last, j);
    plan.read_before_emit[i] = last;
  }
  return plan;
}

std::vector<int> EmitFrames(const DepthPlan& plan) {
  const int n = plan.num_views();
  // When (after which frame) each sparse map can be computed: its frame and those it uses are read.
  auto sparse_ready = [&](int s) {
    int last = s;
    for (int j : plan.uses.at(static_cast<std::size_t>(s))) last = std::max(last, j);
    return last;
  };
  std::vector<int> emit(static_cast<std::size_t>(n), -1);
  for (int i : plan.wanted) {
    if (i < 0 || i >= n) throw OptionError("depth plan: view " + std::to_string(i) + " is not planned");
    int last = std::max(sparse_ready(i), plan.read_before_emit.at(static_cast<std::size_t>(i)));
    for (int j : plan.voters.at(static_cast<std::size_t>(i))) last = std::max(last, sparse_ready(j));
    emit[static_cast<std::size_t>(i)] = last;
  }
  return emit;
}

StreamingDepthStats StreamingDepth::Run(FrameSource& frames, const std::vector<int>& wanted, const Sink& sink) {
  return Run(frames, PlanDepth(views_, options_, wanted), sink);
}

StreamingDepthStats StreamingDepth::Run(FrameSource& frames, const DepthPlan& plan, const Sink& sink) {
  const int n = static_cast<int>(views_.size());
  StreamingDepthStats stats;
  if (plan.num_views() != n || static_cast<int>(plan.uses.size()) != n || static_cast<int>(plan.voters.size()) != n ||
      static_cast<int>(plan.need_sparse.size()) != n || static_cast<int>(plan.read_before_emit.size()) != n)
    throw OptionError("depth plan of " + std::to_string(plan.num_views()) + " views for " + std::to_string(n));
  const std::vector<int>& wanted = plan.wanted;
  const std::vector<char>& on_grid = plan.on_grid;
  const std::vector<char>& need_sparse = plan.need_sparse;
  const std::vector<std::vector<int>>& voters = plan.voters;
  const std::vector<std::vector<int>>& uses = plan.uses;  // frames sparse map s uses besides s
  // When (after which frame) each sparse map can be computed.
  std::vector<int> sparse_ready(n, -1);  // last frame index that sparse map s needs
  std::vector<int> frame_last_use(n, -1);
  for (int s = 0; s < n; ++s) {
    if (!need_sparse[s]) continue;
    int last = s;
    for (int j : uses[s]) last = std::max(last, j);
    sparse_ready[s] = last;
    frame_last_use[s] = std::max(frame_last_use[s], last);
    for (int j : uses[s]) frame_last_use[j] = std::max(frame_last_use[j], last);
  }
  std::vector<int> sparse_last_use(n, -1);
  std::vector<char> is_wanted(n, 0);
  for (int i : wanted)
    if (i < 0 || i >= n || !need_sparse[i]) throw OptionError("depth plan: view " + std::to_string(i) + " is not planned");
  // Every frame within 5° of i is read (and tapped) before i is emitted.
  const std::vector<int> filter_ready = EmitFrames(plan);
  for (int i : wanted) {
    is_wanted[i] = 1;
    const int last = filter_ready[i];
    sparse_last_use[i] = std::max(sparse_last_use[i], last);
    for (int j : voters[i]) sparse_last_use[j] = std::max(sparse_last_use[j], last);
  }
  std::map<int, std::vector<int>> sparse_at, filter_at;  // frame index -> views that complete there
  for (int s = 0; s < n; ++s)
    if (need_sparse[s]) sparse_at[sparse_ready[s]].push_back(s);
  for (int i : wanted) filter_at[filter_ready[i]].push_back(i);
  int last_frame = -1;
  for (int s = 0; s < n; ++s) last_frame = std::max({last_frame, sparse_ready[s], filter_ready[s]});

  const GradientDepthEstimator estimator(options_.gradient);
  std::unique_ptr<SlidingVoteGrid> grid;
  if (options_.run_filter) grid = std::make_unique<SlidingVoteGrid>(volume_, options_.filter);

  std::map<int, ViewImage> held;
  // Sparse maps wait packed (valid pixels only): at 0.12° spacing ~250 of
  // them lie within the filter's 15°, 8.3 MB each at 1280×720 as DepthMaps.
  std::map<int, PackedDepthMap> sparse;
  std::size_t sparse_bytes = 0;
  std::map<int, cv::Mat> reference_frames;  // frames of held views whose sparse map is still to come (CompactFrame)
  std::map<int, cv::Mat> wanted_frames;  // frames of wanted views until they are emitted (CompactFrame)
  Progress progress("depth", static_cast<long long>(wanted.size()));
  Frame frame;
  for (int f = 0; f <= last_frame; ++f) {
    if (!frames.Next(&frame)) throw InputError("frames", "stream ended after " + std::to_string(f) + " of " +
                                                             std::to_string(n) + " frames");
    ++stats.frames_read;
    if (frame.image.cols != views_[f].width || frame.image.rows != views_[f].height)
      throw InputError(frame.name, "frame is " + std::to_string(frame.image.cols) + "x" +
                                       std::to_string(frame.image.rows) + ", its camera " +
                                       std::to_string(views_[f].width) + "x" + std::to_string(views_[f].height));
    if (frame_last_use[f] >= f) {
      ViewImage& v = held[f];
      v.view = views_[f];
      v.image = frame.image;
      v.on_grid = on_grid[f];
      PrepareViewImage(&v, options_.gradient);
    }
    // The frame as it waits (CompactFrame: CV_8UC3 when it is 8-bit), one
    // copy shared by the frames to emit, the references to come and the tap.
    const cv::Mat compact = CompactFrame(frame.image);
    const auto h = held.find(f);
    if (frame_tap_) {
      if (h != held.end()) {
        frame_tap_(f, h->second, compact);
      } else {
        ViewImage v;
        v.view = views_[f];
        v.image = frame.image;
        frame_tap_(f, v, compact);
      }
    }
    const bool reference_later = h != held.end() && need_sparse[f];
    if (is_wanted[f]) wanted_frames[f] = compact;
    if (h != held.end()) {
      // As a neighbour a held frame is read only through its smoothed copy and
      // grey levels; the frame itself is needed again only when the view is a
      // reference (its gradients), so it waits compact (a quarter of the
      // float frame when 8-bit; shared with wanted_frames) and `image` points
      // at `smoothed` meanwhile.
      if (reference_later) reference_frames[f] = compact;
      h->second.image = h->second.smoothed;
    }
    stats.max_frames_held = std::max(stats.max_frames_held, static_cast<int>(held.size()));
    stats.max_pending_frames = std::max(stats.max_pending_frames, static_cast<int>(wanted_frames.size()));

    for (int s : sparse_at[f]) {
      Timer timer;
      std::vector<const ViewImage*> nbs;
      for (int j : uses[s]) nbs.push_back(&held.at(j));
      stats.neighbors_used += static_cast<long long>(uses[s].size());
      ViewImage reference = held.at(s);
      reference.image = ExpandFrame(reference_frames.at(s));
      reference_frames.erase(s);
      sparse[s] = PackedDepthMap::Pack(estimator.Estimate(reference, nbs, volume_));
      sparse_bytes += sparse[s].Bytes();
      stats.seconds_sparse += timer.Seconds();
      stats.cpu_seconds_sparse += timer.CpuSeconds();
      ++stats.sparse_maps;
    }
    stats.max_sparse_held = std::max(stats.max_sparse_held, static_cast<int>(sparse.size()));
    stats.max_sparse_bytes = std::max(stats.max_sparse_bytes, sparse_bytes);
    for (int i : filter_at[f]) {
      const DepthMap own = sparse.at(i).Unpack();
      DepthMap filtered;
      if (options_.run_filter) {
        Timer timer;
        std::set<int> voting(voters[i].begin(), voters[i].end());
        voting.insert(i);
        grid->MoveTo(
            voting, [&](int v) { return sparse.at(v).Unpack(); },
            [&](int v) -> const PinholeView& { return views_[v]; });
        filtered = grid->Filter(own, views_[i]);
        stats.seconds_filter += timer.Seconds();
        stats.cpu_seconds_filter += timer.CpuSeconds();
        ++stats.filtered_maps;
      }
      sink(i, ExpandFrame(wanted_frames.at(i)), own, filtered);
      wanted_frames.erase(i);
      progress.Advance();
    }
    // Release what no pending view needs any more.
    for (auto it = held.begin(); it != held.end();) it = frame_last_use[it->first] <= f ? held.erase(it) : std::next(it);
    for (auto it = sparse.begin(); it != sparse.end();) {
      if (sparse_last_use[it->first] <= f && !(grid && grid->Holds(it->first))) {
        sparse_bytes -= it->second.Bytes();
        it = sparse.erase(it);
      }
      else ++it;
    }
  }
  progress.Finish();
  return stats;
}

}  // namespace lfrecon
