#pragma once
// Runs depth from gradients (§3.1) and voxel-vote filtering (§3.2) over a
// frame stream in sequence order, holding only the frames and sparse maps the
// pending views still need. All poses are known up front (they come with the
// dataset), so each view's neighbourhoods are known before its frames arrive:
// view i's sparse map is computed as soon as the last frame its hierarchy
// uses (within 5°; on a dense sequence only the hierarchy grid's frames and
// the nearest ones, see GradientDepthOptions::level_min_step_deg) has been
// read, and its filtered map as soon as the sparse maps of all views within
// 15° exist. For a dense path that is a window of a few dozen frames.
#include <functional>
#include <vector>

#include "depth/depth_filter.h"
#include "depth/gradient_depth_estimator.h"
#include "io/frame_source.h"

namespace lfrecon {

struct StreamingDepthOptions {
  GradientDepthOptions gradient;
  DepthFilterOptions filter;
  bool run_filter = true;
  // Views more than this many frames apart in the stream are never
  // neighbours (depth, filter, and the pipeline's densification), so no view
  // waits for frames far ahead: without it the first views of a closed loop
  // wait for its last frames (their neighbours across the seam), holding
  // their frames and sparse maps for the whole stream. Shorter sequences
  // (figurines 480 frames) are unaffected. 0: no limit.
  int max_frame_gap = 1000;
  // The filter's voters (§3.2) lie at least this far apart, greedily along
  // the sequence as the hierarchy grid is (FilterVoters); 0 or less than
  // gradient.level_min_step_deg: the grid's own spacing. ReconstructionPlan
  // sets it to the view selection's step, so that only the selected views
  // need sparse maps (figurines, views 1° apart: sparse stage 114 -> 51 CPU-s;
  // the vote saturation is relative to the window, see DepthFilterOptions).
  double voter_min_step_deg = 0;
  void Check() const;
};

struct StreamingDepthStats {
  int frames_read = 0;
  int sparse_maps = 0;
  int filtered_maps = 0;
  int max_frames_held = 0;
  int max_sparse_held = 0;
  // Frames of wanted views read but not yet emitted (held as CV_8UC3 when they
  // are 8-bit; at the 3000-frame loop's spacing each waits for the sparse maps
  // 15° ahead).
  int max_pending_frames = 0;
  // Peak heap bytes of the sparse maps held (packed: valid pixels only).
  std::size_t max_sparse_bytes = 0;
  long long neighbors_used = 0;  // summed over the sparse maps (the views each one's hierarchy used)
  double seconds_sparse = 0;
  double seconds_filter = 0;
  double cpu_seconds_sparse = 0;  // process CPU (all threads) during the same sections
  double cpu_seconds_filter = 0;
};

class ViewGraph;

// What the depth stage computes over a sequence, and from which frames: the
// depth part of the job's reconstruction plan (libs/pipeline ReconstructionPlan
// holds one; PlanDepth computes it). Per frame index.
struct DepthPlan {
  std::vector<int> wanted;             // views whose filtered maps are emitted, increasing
  std::vector<char> on_grid;           // HierarchyGrid: usable beyond the hierarchy's first level
  std::vector<char> need_sparse;       // a sparse map is computed: the wanted views and their voters
  std::vector<std::vector<int>> uses;  // need_sparse: the frames its sparse map uses, in SelectHierarchyViews order
  std::vector<std::vector<int>> voters;  // wanted (with the filter): FilterVoters, increasing
  // wanted: every frame up to this one is read (and tapped) before the view is
  // emitted: its neighbours within gradient.max_view_angle_deg.
  std::vector<int> read_before_emit;
  int num_views() const { return static_cast<int>(on_grid.size()); }
};

// The depth plan of `views` (a sequence) for the views `wanted` (all when
// empty; checked against the range, then sorted and made unique). View s's
// entries need only the cameras within max_frame_gap and the filter's angle of
// it (and on_grid, which depends on the cameras before it only). Throws OptionError.
DepthPlan PlanDepth(const std::vector<PinholeView>& views, const StreamingDepthOptions& options,
                    std::vector<int> wanted);

// After which frame of the sequence StreamingDepth::Run emits each view of
// plan.wanted (its sparse map, its voters' and every frame within the angle are
// then computed and read); -1 for the others. Run emits the wanted views in
// increasing order of it, ties in increasing view order.
std::vector<int> EmitFrames(const DepthPlan& plan);

// The views whose sparse maps vote in view i's filtered map (§3.2): its
// neighbours within the filter's angle (`wide`) that may vote (`can_vote`).
// PlanDepth lets the views on the hierarchy grid vote (HierarchyGrid: views ≥
// level_min_step_deg apart): on a dense sequence (0.12° at 3000 frames a
// loop) ~60 instead of ~250, whose sparse maps would otherwise all wait in
// memory for the filter; or, with StreamingDepthOptions::voter_min_step_deg,
// the views that far apart (the pipeline's view selection: then the voters
// are the processed views, and no other view needs a sparse map).
std::vector<int> FilterVoters(const ViewGraph& wide, const std::vector<char>& can_vote, int i);

class StreamingDepth {
 public:
  // view_index, its frame (CV_32FC3), sparse map, filtered map (empty if run_filter is false).
  using Sink = std::function<void(int, const cv::Mat&, const DepthMap&, const DepthMap&)>;

  StreamingDepth(std::vector<PinholeView> views, const BoundingBox& volume, const StreamingDepthOptions& options);

  // Reads `frames` in order (its frame k is view k) and calls `sink` for every
  // view in `wanted` (all views when empty), in the order they complete.
  StreamingDepthStats Run(FrameSource& frames, const std::vector<int>& wanted, const Sink& sink);
  // The same with the plan given (PlanDepth of these views and options, or a
  // ReconstructionPlan's depth part).
  StreamingDepthStats Run(FrameSource& frames, const DepthPlan& plan, const Sink& sink);

  // Optional: called once for every frame read, in sequence order, before any
  // sink call at that frame. The ViewImage is the one the depth stage holds
  // (smoothed/grey filled) when it keeps the frame, else view + image only.
  // Every frame within gradient.max_view_angle_deg of view i has been tapped
  // before sink(i) is called, so a consumer can keep its own window of the
  // neighbours' frames (the embedded pipeline's densification does). The
  // cv::Mat is CompactFrame of the frame, the copy the stage itself keeps
  // while it needs the frame: a consumer that keeps it shares those pixels.
  using FrameTap = std::function<void(int, const ViewImage&, const cv::Mat&)>;
  void SetFrameTap(FrameTap tap) { frame_tap_ = std::move(tap); }

 private:
  std::vector<PinholeView> views_;
  BoundingBox volume_;
  StreamingDepthOptions options_;
  FrameTap frame_tap_;
};

}  // namespace lfrecon
