#pragma once
// Free-space evidence added to a view's depth map before fusion (ours): what
// the propagation (§4) leaves without confidence where the background has no
// texture, from two sources, each a function from a map to a map so that
// `lfrecon run` and the service's aggregator apply the same one.
#include <opencv2/core.hpp>

#include "depth/depth_map.h"
#include "geometry/pinhole_view.h"
#include "geometry/triangle_mesh.h"

namespace lfrecon {

// Background free space (PipelineOptions::background_floor says why and
// what it measured): depths whose point lies outside V and that are not
// labelled foreground (the ray passes through V to the background), at least
// `gate_px` pixels (Euclidean) from every foreground depth (labelled
// foreground, or a point inside V) and from every nonzero pixel of `protect`
// (CV_8U of the map's size; empty: none), get confidence >= `floor`.
DepthMap WithGatedBackgroundFloor(const DepthMap& map, const PinholeView& view, const BoundingBox& volume,
                                  double floor, double gate_px, const cv::Mat& protect = cv::Mat());

// Free space from an object mask (PipelineOptions::mask_free_space): a pixel
// more than `margin_px` pixels (Euclidean) from every object pixel of `mask`
// (CV_8U of the map's size, nonzero = the object) sees no object, so its
// whole ray through V is empty: it becomes background with depth 0 (the
// fusion's "whole ray through V free", surface_evidence.h) and confidence
// max(its own background confidence, `confidence`), whatever the map said
// there: a halo's foreground depth (propagated over a background of even
// colour, where no photometric test can see it) is replaced. Pixels near the
// object, and maps without a usable mask (empty, or another size), are left
// as they are.
DepthMap WithMaskFreeSpace(const DepthMap& map, const cv::Mat& mask, double confidence, double margin_px);

}  // namespace lfrecon
