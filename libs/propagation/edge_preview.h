#pragma once
// A preview for people: the frame in dimmed grey with silhouette edges and
// texture edges (bidirectional photoconsistency, §4.1) drawn in two colours,
// as in the paper's Fig. 4 (bottom), with a legend.
#include <filesystem>
#include <opencv2/core.hpp>

namespace lfrecon {

// Colours (BGR): silhouette edges orange, texture edges blue (distinct for
// the common colour-vision deficiencies); unresolved pixels are not drawn.
inline const cv::Scalar kSilhouetteColor(0, 140, 255);
inline const cv::Scalar kTextureColor(255, 160, 30);

// `frame`: CV_32FC3 in [0, 1] or CV_8UC3; `edge_classes`: CV_8U EdgeClass values
// (EdgeConsistency::Classify). Returns CV_8UC3.
cv::Mat RenderEdgePreview(const cv::Mat& frame, const cv::Mat& edge_classes, bool legend = true);
// Writes RenderEdgePreview as PNG (or by extension); throws InputError naming the file.
void WriteEdgePreview(const std::filesystem::path& path, const cv::Mat& frame, const cv::Mat& edge_classes);

}  // namespace lfrecon
