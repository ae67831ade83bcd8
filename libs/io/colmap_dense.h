#pragma once
// COLMAP's dense depth and normal maps (src/colmap/mvs/mat.{h,cc}): a text
// header "WIDTH&HEIGHT&CHANNELS&" followed by float32 little-endian values,
// channel planes one after the other, each plane row-major (value (row, col,
// channel) at channel * W * H + row * W + col). Depth is planar, 0 where
// there is none; normal maps are 3 channels, unit, in camera coordinates.
// These are the files of a COLMAP dense workspace's stereo/depth_maps/ and
// stereo/normal_maps/ that `colmap stereo_fusion` and OpenMVS read.
#include <filesystem>
#include <opencv2/core.hpp>

namespace lfrecon {

// CV_32F (1 channel) or CV_32FC3 maps; throws InputError naming the file.
void WriteColmapDenseMap(const std::filesystem::path& path, const cv::Mat& map);
// Returns CV_32F or CV_32FC<channels> (at most 4 channels, 2^26 values).
cv::Mat ReadColmapDenseMap(const std::filesystem::path& path);

}  // namespace lfrecon
