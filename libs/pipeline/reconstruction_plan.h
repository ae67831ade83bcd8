#pragma once
// The reconstruction plan of a job: which views get depth, densification and
// fusion (view selection), each view's depth neighbours and their
// hierarchy-grid flags (ViewImage::on_grid), the filter's voters, the
// photoconsistency neighbours, the colour and carving frames, and the fusion
// grid's options. Computed once per job from the cameras and the options
// (ReconstructionPlan::Compute, the one place), and used by `lfrecon run`
// (EmbeddedPipeline, StreamingDepth through plan.depth), by the service's
// aggregator (what each task lists, when it is ready, when the job is done)
// and by both workers (the on_grid flags of the frames a depth task reads), so
// the two paths cannot drift apart.
//
// Growing with the stream (open-ended jobs): selection and on_grid are greedy
// along the sequence (view k's flags depend on the cameras before it only);
// view i's neighbours, voters and photoconsistency neighbours need only the
// cameras within max_frame_gap frames and the stage's angle of it. Only the
// colour and carving frames (evenly spread over the selected views) need the
// whole sequence.
#include <vector>

#include "depth/streaming_depth.h"
#include "fusion/fusion_options.h"
#include "geometry/pinhole_view.h"
#include "geometry/triangle_mesh.h"
#include "pipeline/pipeline_options.h"

namespace lfrecon {

struct ReconstructionPlan {
  // Throws OptionError (bad options, a view in options.views out of range, no views).
  static ReconstructionPlan Compute(const std::vector<PinholeView>& views, const BoundingBox& volume,
                                    const PipelineOptions& options);

  // Growing with the stream: of a sequence of which the first `received`
  // frames are known (the whole sequence when `ended`), the number of leading
  // frames whose entries (selected, on_grid, need_sparse, depth neighbours,
  // voters, read_before_emit, photoconsistency neighbours) are final: Compute
  // on the first `received` cameras gives them exactly as Compute on the whole
  // sequence. Frame i's entries need the cameras up to i + max_frame_gap (its
  // own neighbours, voters and photo neighbours), and a voter's sparse-map
  // neighbours up to i + 2 max_frame_gap; with max_frame_gap 0 (unbounded)
  // nothing is final before the end. Colour and carving frames are final only
  // at the end. Only for options.views empty (an explicit list is not grown).
  static int SettledFrames(int received, bool ended, const PipelineOptions& options);
  // The same for the depth stage alone: the leading frames whose need_sparse and
  // depth neighbours are final (received - max_frame_gap; all at the end; none
  // before the end without a gap limit or with given views). A sparse map computed
  // then is the full plan's, so the voters of the SettledFrames views have
  // theirs one gap earlier. Every received frame's selection and on_grid flag are
  // final (greedy along the sequence): a worker may use them for any frame.
  static int SettledDepthFrames(int received, bool ended, const PipelineOptions& options);

  int num_views() const { return static_cast<int>(selected.size()); }
  // Of an open stream's plan (Compute on its first num_views() frames): the
  // leading entries of `order` that the whole stream's plan has in the same
  // places (settled views emitted before the first unsettled frame, which no
  // view of a later frame precedes); all of them when `ended`.
  int FinalOrder(bool ended, const PipelineOptions& options) const;
  bool Selected(int i) const { return selected.at(static_cast<std::size_t>(i)) != 0; }
  bool OnGrid(int i) const { return depth.on_grid.at(static_cast<std::size_t>(i)) != 0; }
  bool NeedsSparse(int i) const { return depth.need_sparse.at(static_cast<std::size_t>(i)) != 0; }
  // Frames view i's sparse map uses besides i, in the order the estimator takes them.
  const std::vector<int>& DepthNeighbours(int i) const { return depth.uses.at(static_cast<std::size_t>(i)); }
  // Sparse maps voting in view i's filtered map besides i's own (selected views, with the filter).
  const std::vector<int>& Voters(int i) const { return depth.voters.at(static_cast<std::size_t>(i)); }
  // Frames on the hierarchy grid (OnGrid) within the photoconsistency angle of
  // view i (selected views, when densifying), nearest first.
  const std::vector<int>& PhotoNeighbours(int i) const { return photo.at(static_cast<std::size_t>(i)); }

  std::vector<char> selected;  // per frame: gets depth, densification and fusion
  std::vector<int> views;      // the selected views, increasing
  DepthPlan depth;             // StreamingDepth's part (wanted = views)
  // The selected views in the order the depth stage completes them
  // (EmitFrames: by the frame after which each is emitted, ties by view):
  // lfrecon run densifies and fuses them in this order, the service's
  // aggregator fuses them in it, and the geometric consistency check's
  // neighbours are the views around each in it (a closed loop's first views
  // come last, beside its last ones).
  std::vector<int> order;
  std::vector<int> emit_frame;      // per frame: EmitFrames (-1: not selected)
  std::vector<int> order_position;  // per frame: its index in `order` (-1: not selected)
  std::vector<std::vector<int>> photo;
  std::vector<int> color_frames;    // options.color_views frames evenly spread over `views`
  std::vector<int> carving_frames;  // options.carving_views likewise, when refining with carving
  FusionOptions fusion;             // PipelineFusionOptions for V
};

// View selection alone (ViewSelectionOptions): the selected indices, increasing.
std::vector<int> SelectViews(const std::vector<PinholeView>& views, const ViewSelectionOptions& options);

// `k` of `views` evenly spread (views[c * size / k], c < k), as the colour and carving frames are chosen.
std::vector<int> EvenlySpread(const std::vector<int>& views, int k);

}  // namespace lfrecon
