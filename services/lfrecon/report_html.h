#pragma once
// OUT/report.html: one self-contained page (images as data URIs) a person opens
// in a browser: the turntable render and beside it a few views' depth and edge
// previews (preview/ and edges/, which lfrecon run writes; else depth/*.pfm),
// per-stage times and memory from report.json, and the evaluation against
// ground truth when there is one.
#include <filesystem>
#include <optional>

namespace lfrecon::cli {

struct ReportHtmlOptions {
  // Ground truth to score OUT/mesh.ply against (OUT/eval.json written); else
  // an OUT/eval.json already there (lfrecon eval --json) is shown.
  std::optional<std::filesystem::path> gt_mesh;
  std::optional<std::filesystem::path> gt_thin;
  int max_previews = 4;  // depth and edge previews, spread over the views
};

// Reads OUT/report.json (InputError naming it if absent or malformed) and
// whatever of mesh_turntable.png, preview/*.png, depth/*.pfm, edges/*.png, eval.json is in
// `out`; writes OUT/report.html and returns its path.
std::filesystem::path WriteReportHtml(const std::filesystem::path& out, const ReportHtmlOptions& options);

}  // namespace lfrecon::cli
