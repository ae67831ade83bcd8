#include "report_html.h"

#include <CLI/CLI.hpp>
#include <iostream>
#include <memory>

#include "commands.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "eval/mesh_metrics.h"
#include "io/depth_map_io.h"
#include "io/frame_source.h"
#include "io/json_file.h"
#include "io/ply.h"
#include "util/error.h"

namespace lfrecon::cli {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

std::string Escape(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string Base64(const std::vector<uchar>& bytes) {
  static const char* k = "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
  std::string out;
  out.reserve((bytes.size() + 2) / 3 * 4);
  for (std::size_t i = 0; i < bytes.size(); i += 3) {
    const std::uint32_t b0 = bytes[i], b1 = i + 1 < bytes.size() ? bytes[i + 1] : 0,
                        b2 = i + 2 < bytes.size() ? bytes[i + 2] : 0;
    const std::uint32_t v = (b0 << 16) | (b1 << 8) | b2;
    out += k[(v >> 18) & 63];
    out += k[(v >> 12) & 63];
    out += i + 1 < bytes.size() ? k[(v >> 6) & 63] : '=';
    out += i + 2 < bytes.size() ? k[v & 63] : '=';
  }
  return out;
}

// An <img> of an 8-bit image, PNG-encoded into a data URI.
std::string ImgTag(const cv::Mat& image, const std::string& alt) {
  std::vector<uchar> png;
  cv::imencode(".png", image, png);
  // Small maps shown at least 320 px wide (the decoded width stays the image's own).
  return "<img src=\"data:image/png;base64," + Base64(png) + "\" alt=\"" + Escape(alt) + "\" width=\"" +
         std::to_string(std::max(image.cols, 320)) + "\" style=\"image-rendering:pixelated\">";
}

std::string Fixed(double v, int digits) {
  std::ostringstream ss;
  ss << std::fixed << std::setprecision(digits) << v;
  return ss.str();
}

// `n` files of `dir` with `ext`, spread evenly over their natural order.
std::vector<fs::path> Spread(const fs::path& dir, const std::string& ext, int n) {
  std::vector<fs::path> all;
  std::error_code ec;
  if (!fs::is_directory(dir, ec)) return all;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.is_regular_file() && e.path().extension() == ext) all.push_back(e.path());
  std::sort(all.begin(), all.end(),
            [](const fs::path& a, const fs::path& b) { return NaturalNameLess(a.filename().string(), b.filename().string()); });
  std::vector<fs::path> out;
  const int m = static_cast<int>(all.size());
  for (int k = 0; k < std::min(n, m); ++k) out.push_back(all[static_cast<std::size_t>(k) * m / std::min(n, m)]);
  return out;
}

json Evaluate(const fs::path& mesh_path, const ReportHtmlOptions& o, const json& report) {
  const TriangleMesh mesh = ReadPly(mesh_path);
  const TriangleMesh gt = ReadPly(*o.gt_mesh);
  TriangleMesh thin;
  if (o.gt_thin) thin = ReadPly(*o.gt_thin);
  MeshMetricsOptions mo;
  if (report.contains("volume")) {
    BoundingBox v;
    for (int k = 0; k < 3; ++k) {
      v.min[k] = report["volume"]["min"][k].get<double>();
      v.max[k] = report["volume"]["max"][k].get<double>();
    }
    mo.volume = v;
  }
  const MeshMetrics m = EvaluateMesh(mesh, gt, thin.triangles.empty() ? nullptr : &thin, mo);
  json j;
  j["mesh"] = mesh_path.string();
  j["ground_truth"] = o.gt_mesh->string();
  j["scores"] = json::array();
  for (const ThresholdScore& s : m.scores)
    j["scores"].push_back({{"threshold_mm", s.threshold * 1000},
                           {"precision", s.precision},
                           {"recall", s.recall},
                           {"fscore", s.fscore},
                           {"thin_recall", s.thin_recall < 0 ? json() : json(s.thin_recall)}});
  j["median_accuracy_mm"] = m.median_accuracy * 1000;
  j["median_completeness_mm"] = m.median_completeness * 1000;
  return j;
}

}  // namespace

fs::path WriteReportHtml(const fs::path& out, const ReportHtmlOptions& o) {
  const fs::path report_path = out / "report.json";
  const json report = ReadJsonFile(report_path);
  if (!report.is_object()) throw InputError(report_path.string(), "not a JSON object");
  std::ostringstream h;
  h << "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>lfrecon report: "
    << Escape(out.filename().string()) << "</title>\n<style>body{font-family:sans-serif;margin:2em;max-width:70em}"
    << "table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:.2em .6em;text-align:right}"
    << "th:first-child,td:first-child{text-align:left}figure{display:inline-table;margin:.5em;vertical-align:top}"
    // A caption wraps within its image's width, so a view's depth and edges stay side by side.
    << "figcaption{display:table-caption;caption-side:bottom}"
    << ".view{display:flex;flex-wrap:wrap;align-items:flex-start}"
    << "img{max-width:100%;border:1px solid #ddd}</style></head><body>\n";
  h << "<h1>lfrecon report</h1>\n<p>Run folder <code>" << Escape(fs::absolute(out).string()) << "</code>";
  if (report.contains("views"))
    h << "; " << report["views"].value("processed", 0) << " of " << report["views"].value("total", 0)
      << " views processed";
  if (report.contains("voxel_size")) h << "; voxel " << Fixed(1000 * report["voxel_size"].get<double>(), 2) << " mm";
  if (report.contains("counts") && report["counts"].contains("mesh_triangles"))
    h << "; mesh " << report["counts"]["mesh_vertices"] << " vertices, " << report["counts"]["mesh_triangles"]
      << " triangles";
  h << ".</p>\n";

  // The mesh, and beside it a few views' depth and edges.
  h << "<h2>Mesh, depth and edges</h2>\n";
  const fs::path turntable = out / "mesh_turntable.png";
  std::error_code ec;
  if (fs::is_regular_file(turntable, ec)) {
    const cv::Mat t = cv::imread(turntable.string(), cv::IMREAD_COLOR);
    if (t.empty()) throw InputError(turntable.string(), "cannot read the turntable render");
    h << "<figure>" << ImgTag(t, "turntable render of mesh.ply") << "<figcaption>mesh.ply, turntable</figcaption></figure>\n";
  } else {
    h << "<p>No turntable render (mesh_turntable.png).</p>\n";
  }
  // Depth and edge previews of a few views, each view's side by side: the views
  // of preview/ (lfrecon run and lfrecon depth write it), else of depth/ (PFM:
  // lfrecon run --write-depth), else of edges/.
  std::vector<fs::path> previewed = Spread(out / "preview", ".png", o.max_previews);
  if (previewed.empty()) previewed = Spread(out / "depth", ".pfm", o.max_previews);
  if (previewed.empty()) previewed = Spread(out / "edges", ".png", o.max_previews);
  if (previewed.empty())
    h << "<p>No depth or edge previews in this folder (lfrecon run --previews N writes them).</p>\n";
  for (const fs::path& p : previewed) {
    const std::string stem = p.stem().string();
    const fs::path preview = out / "preview" / (stem + ".png"), pfm = out / "depth" / (stem + ".pfm"),
                   edges = out / "edges" / (stem + ".png");
    h << "<div class=\"view\">";
    if (fs::is_regular_file(preview, ec)) {
      const cv::Mat d = cv::imread(preview.string(), cv::IMREAD_COLOR);
      if (d.empty()) throw InputError(preview.string(), "cannot read the depth preview");
      h << "<figure>" << ImgTag(d, "depth " + stem) << "<figcaption>depth " << Escape(stem)
        << " (frame and fused depth, turbo, 2nd-98th percentile)</figcaption></figure>";
    } else if (fs::is_regular_file(pfm, ec)) {
      h << "<figure>" << ImgTag(ColorizeMap(ReadPfm(pfm)), "depth " + stem) << "<figcaption>depth " << Escape(stem)
        << " (turbo, 2nd-98th percentile)</figcaption></figure>";
    }
    if (fs::is_regular_file(edges, ec)) {
      const cv::Mat e = cv::imread(edges.string(), cv::IMREAD_COLOR);
      if (e.empty()) throw InputError(edges.string(), "cannot read the edge preview");
      h << "<figure>" << ImgTag(e, "edges " + stem) << "<figcaption>edges " << Escape(stem)
        << " (dense stage: silhouette orange, texture blue)</figcaption></figure>";
    }
    h << "</div>\n";
  }
  std::vector<std::string> files;
  for (const char* f : {"mesh.ply", "mesh.obj", "mesh.glb", "mesh_raw.ply", "points.ply", "grid.vdb"})
    if (fs::is_regular_file(out / f, ec)) files.push_back(f);
  if (fs::is_directory(out / "colmap", ec)) files.push_back("colmap/ (COLMAP dense workspace)");
  h << "<p>Files: ";
  for (std::size_t i = 0; i < files.size(); ++i) h << (i ? ", " : "") << "<code>" << Escape(files[i]) << "</code>";
  h << "</p>\n";

  // Times and memory.
  h << "<h2>Time and memory</h2>\n<table><tr><th>stage</th><th>seconds</th><th>share</th></tr>\n";
  double total = 0;
  if (report.contains("seconds") && report["seconds"].contains("total")) total = report["seconds"]["total"].get<double>();
  if (report.contains("seconds"))
    for (const auto& [stage, s] : report["seconds"].items()) {
      if (!s.is_number()) continue;
      // "fusion_update" is part of "fusion": shown indented under it.
      const auto cut = stage.rfind('_');
      const bool part = cut != std::string::npos && report["seconds"].contains(stage.substr(0, cut));
      h << "<tr><td" << (part ? " style=\"padding-left:2em\"" : "") << ">" << Escape(stage) << "</td><td>"
        << Fixed(s.get<double>(), 2) << "</td><td>"
        << (total > 0 && stage != "total" ? Fixed(100 * s.get<double>() / total, 1) + " %" : "") << "</td></tr>\n";
    }
  if (report.contains("pose_refinement") && report["pose_refinement"].contains("seconds"))
    h << "<tr><td>pose refinement (before the pipeline)</td><td>"
      << Fixed(report["pose_refinement"]["seconds"].get<double>(), 2) << "</td><td></td></tr>\n";
  h << "</table>\n<p>";
  if (report.contains("peak_rss_bytes"))
    h << "Peak memory (RSS) " << Fixed(report["peak_rss_bytes"].get<double>() / 1048576.0, 0) << " MiB";
  if (report.contains("counts")) {
    const json& c = report["counts"];
    if (c.contains("grid_bytes")) h << "; fusion grid " << Fixed(c["grid_bytes"].get<double>() / 1048576.0, 1) << " MiB";
    if (c.contains("depth_store_bytes"))
      h << "; depth store " << Fixed(c["depth_store_bytes"].get<double>() / 1048576.0, 1) << " MiB";
    if (c.contains("max_frames_held_pipeline")) h << "; at most " << c["max_frames_held_pipeline"] << " frames held";
  }
  h << ".</p>\n";

  // Evaluation.
  json eval;
  if (o.gt_mesh && fs::is_regular_file(out / "mesh.ply", ec)) {
    eval = Evaluate(out / "mesh.ply", o, report);
    std::ofstream(out / "eval.json") << eval.dump(2) << "\n";
  } else if (fs::is_regular_file(out / "eval.json", ec)) {
    eval = ReadJsonFile(out / "eval.json");
  }
  h << "<h2>Evaluation against ground truth</h2>\n";
  if (eval.is_object() && eval.contains("scores") && eval["scores"].is_array()) {
    h << "<table id=\"evaluation\"><tr><th>threshold</th><th>precision</th><th>recall</th><th>F-score</th><th>thin recall</th></tr>\n";
    for (const json& s : eval["scores"]) {
      auto cell = [&](const char* key) {
        return s.contains(key) && s[key].is_number() ? Fixed(s[key].get<double>(), 3) : std::string("–");
      };
      h << "<tr><td>" << Fixed(s.value("threshold_mm", 0.0), 0) << " mm</td><td>" << cell("precision") << "</td><td>"
        << cell("recall") << "</td><td>" << cell("fscore") << "</td><td>" << cell("thin_recall") << "</td></tr>\n";
    }
    h << "</table>\n";
    if (eval.contains("median_accuracy_mm"))
      h << "<p>Median accuracy " << Fixed(eval["median_accuracy_mm"].get<double>(), 2) << " mm, median completeness "
        << Fixed(eval.value("median_completeness_mm", 0.0), 2) << " mm (against <code>"
        << Escape(eval.value("ground_truth", std::string())) << "</code>).</p>\n";
  } else {
    h << "<p>No ground truth for this dataset.</p>\n";
  }
  h << "<h2>report.json</h2>\n<details><summary>all figures</summary><pre>" << Escape(report.dump(2))
    << "</pre></details>\n";
  // For headless checks (tests/cli): each image's decoded width, once loaded.
  h << "<script>window.addEventListener('load',function(){var n=0;for(var i=0;i<document.images.length;++i){"
       "var im=document.images[i];im.setAttribute('data-natural-width',String(im.naturalWidth));"
       "if(im.complete&&im.naturalWidth>0)++n;}document.body.setAttribute('data-images-loaded',String(n));});"
       "</script>\n</body></html>\n";
  const fs::path html = out / "report.html";
  std::ofstream f(html, std::ios::trunc);
  f << h.str();
  f.close();
  if (!f) throw InputError(html.string(), "cannot write");
  return html;
}

void AddReportCommand(CLI::App& root, int* exit_code) {
  struct Args {
    fs::path run;
    fs::path gt, gt_thin;
    int previews = 4;
  };
  auto a = std::make_shared<Args>();
  auto* cmd = root.add_subcommand("report", "Write RUN/report.html from a run folder (lfrecon run writes it too)");
  cmd->add_option("--run", a->run, "Run folder (report.json, mesh_turntable.png, preview/, depth/, edges/, eval.json)")->required();
  cmd->add_option("--gt", a->gt, "Ground-truth mesh to score RUN/mesh.ply against (else RUN/eval.json if present)");
  cmd->add_option("--gt-thin", a->gt_thin, "Its thin parts (thin-feature recall)");
  cmd->add_option("--previews", a->previews, "Depth and edge previews shown")->capture_default_str();
  cmd->callback([a, exit_code] {
    if (a->previews < 0) throw OptionError("--previews must be >= 0");
    ReportHtmlOptions o;
    if (!a->gt.empty()) o.gt_mesh = a->gt;
    if (!a->gt_thin.empty()) o.gt_thin = a->gt_thin;
    o.max_previews = a->previews;
    std::cout << WriteReportHtml(a->run, o).string() << "\n";
    *exit_code = 0;
  });
}

}  // namespace lfrecon::cli
