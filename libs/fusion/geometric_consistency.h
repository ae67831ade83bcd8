#pragma once
// Multi-view geometric consistency of the dense maps before fusion (ours; the
// standard MVS fusion filter of COLMAP's and OpenMVS's stereo fusion): a
// foreground depth (its point inside V) is kept only where enough of the
// neighbouring views' dense maps see the same point. Propagation (§4.2) fills
// low-texture background beside an object with the object's depth (the
// "halo"); each view's halo lies elsewhere in space, so the neighbours'
// maps do not confirm it, while a surface seen by several views does.
//
// Depths that are the view's own filtered depth (§3.1-§3.2: an edge pixel,
// including the thin parts' contested silhouettes that the propagation keeps,
// PropagationOptions::keep_contested_foreground) are not checked: a thin part
// is foreground in a minority of the views' dense maps, and any vote among
// neighbours removes it (docs/benchmarks.md, "Multi-view geometric
// consistency"). Measured there with fusion_from_depth_bench on the maps of
// `lfrecon run --write-depth` (offsets 1/2/4/8, 4 of 8, 1 %, own depths
// spared): figurines F@5 0.701 -> 0.721, P@5 0.770 -> 0.824, thin@5 0.899 ->
// 0.930; tabletop (320x180) F@5 0.837 -> 0.850, P@5 0.871 -> 0.906, thin@5
// 0.500 -> 0.470.
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "depth/depth_map.h"
#include "geometry/pinhole_view.h"
#include "geometry/triangle_mesh.h"

namespace lfrecon {

struct GeometricConsistencyOptions {
  // On by default, in lfrecon run and in the service's aggregator alike
  // (--no-geometric-consistency turns it off).
  bool enabled = true;
  // The neighbours: the plan's views at these offsets before and after the
  // view in the order they are processed (ReconstructionPlan::order; >= 2°
  // apart by default: 2°, 4°, 8°, 16°). A view is fused once the maps of its
  // neighbours are there, i.e. max(offsets) views late.
  std::vector<int> offsets = {1, 2, 4, 8};
  // Neighbour maps that must agree (of up to 2 · offsets.size()): at least
  // min_agree, and at least this fraction of the neighbours the view has (a
  // view at the end of an arc has fewer). 1: every neighbour must see the
  // point, measured in docs/benchmarks.md ("Every neighbour must agree"):
  // with redundant views a dropped right depth costs little, a kept wrong one
  // a sheet.
  int min_agree = 4;
  double min_agree_fraction = 1.0;
  // Agreement: the neighbour's depth at the point's projection (nearest pixel)
  // within this fraction of the point's depth in that view.
  double depth_tolerance = 0.01;
  // A dense depth within this fraction of the view's own filtered depth at the
  // same pixel counts as its own (not checked).
  double own_tolerance = 0.01;

  // The views a map waits for: max(offsets) when enabled, else 0.
  int Delay() const;
  void Check() const;  // throws OptionError
};

struct GeometricConsistencyStats {
  long long foreground = 0;  // depths whose point lies inside V
  long long own = 0;         // of them, the view's own filtered depth (not checked)
  long long dropped = 0;     // of them, confirmed by too few neighbours (min_agree, min_agree_fraction): removed
};

// The positions of a view's neighbours in a list of `count` views (the plan's):
// position ± each offset, those in [0, count), nearest first.
std::vector<int> NeighbourPositions(int position, int count, const GeometricConsistencyOptions& options);

// Nonzero where `dense` has a depth within `tolerance` (relative) of `filtered`'s at the same pixel.
cv::Mat OwnDepthMask(const DepthMap& dense, const DepthMap& filtered, double tolerance);

// A neighbouring view and its dense depth (CV_32F planar depth, 0 where none).
struct NeighbourDepth {
  const PinholeView* view = nullptr;
  const cv::Mat* depth = nullptr;
};

// Removes (depth, confidence and label to zero) every foreground depth of
// `map` that is not its own (`own`: CV_8U of the map's size, nonzero = own;
// empty: none) and that fewer than max(options.min_agree, ⌈min_agree_fraction ·
// the neighbours given⌉) of `neighbours` confirm.
// A neighbour confirms when the point projects into its image in front of it
// and its depth at the nearest pixel is within depth_tolerance of the point's
// depth there. Deterministic; `map` may be shared with no one else.
GeometricConsistencyStats ApplyGeometricConsistency(const PinholeView& view, const cv::Mat& own,
                                                    const std::vector<NeighbourDepth>& neighbours,
                                                    const BoundingBox& volume,
                                                    const GeometricConsistencyOptions& options, DepthMap* map);

}  // namespace lfrecon
