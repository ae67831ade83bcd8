// report.html (issue 17): written from a run folder by `lfrecon report` and by
// `lfrecon run` (with its own depth and edge previews), loaded in headless
// Chromium, which must decode every image on the page; and `lfrecon run`'s
// export flags.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

namespace {

namespace fs = std::filesystem;

struct Result {
  int code = -1;
  std::string output;  // stdout and stderr together
};

Result Shell(const std::string& cmd) {
  Result r;
  FILE* pipe = popen((cmd + " 2>&1").c_str(), "r");
  if (!pipe) return r;
  std::array<char, 4096> buf;
  size_t n;
  while ((n = fread(buf.data(), 1, buf.size(), pipe)) > 0) r.output.append(buf.data(), n);
  const int status = pclose(pipe);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return r;
}

Result Cli(const std::string& args) { return Shell(std::string(LFRECON_CLI) + " " + args); }

struct Dir {
  fs::path path;
  explicit Dir(const std::string& name)
      : path(fs::temp_directory_path() / ("lfrecon_report_test_" + name + "_" + std::to_string(getpid()))) {
    fs::remove_all(path);
    fs::create_directories(path);
  }
  ~Dir() { fs::remove_all(path); }
};

std::string ReadFile(const fs::path& p) {
  std::ifstream f(p, std::ios::binary);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

std::string Chromium() {
  for (const char* c : {"/usr/bin/chromium", "/usr/bin/chromium-browser"})
    if (fs::exists(c)) return c;
  return "";
}

// A PNG's width from its IHDR chunk (big-endian, bytes 16-19).
int PngWidth(const fs::path& png) {
  const std::string b = ReadFile(png);
  if (b.size() < 24 || b.substr(1, 3) != "PNG") return -1;
  int w = 0;
  for (int k = 16; k < 20; ++k) w = (w << 8) | static_cast<unsigned char>(b[static_cast<std::size_t>(k)]);
  return w;
}

// A run folder with every part the page shows: report.json, the turntable,
// a depth map and an edge preview (from `lfrecon depth --stage dense`), and
// the ground truth as mesh.ply (so the evaluation is perfect).
void MakeRunFolder(const fs::path& data, const fs::path& run) {
  ASSERT_EQ(Cli("-q synth --scene sphere --frames 60 --width 96 --height 54 --out " + data.string()).code, 0);
  const Result depth = Cli("-q depth --dataset " + data.string() + " --out " + run.string() +
                           " --views 30:31 --stage dense");
  ASSERT_EQ(depth.code, 0) << depth.output;
  fs::copy_file(run / "preview" / "00030.png", run / "mesh_turntable.png");
  fs::copy_file(data / "gt_mesh.ply", run / "mesh.ply");
  std::ofstream(run / "report.json") << R"({
    "counts": {"mesh_vertices": 14707, "mesh_triangles": 29410, "grid_bytes": 1048576},
    "peak_rss_bytes": 314572800,
    "seconds": {"depth_sparse": 12.5, "fusion": 7.25, "total": 25.0},
    "views": {"processed": 60, "total": 60},
    "volume": {"min": [-0.16, -0.16, 0.09], "max": [0.16, 0.16, 0.41]},
    "voxel_size": 0.00125
  })";
}

// `html` loaded in headless Chromium: how many images decoded, and "alt=decoded
// width" of each in page order (the page's script writes both). Empty optional
// when Chromium is not installed.
struct LoadedPage {
  std::string images_loaded;
  std::vector<std::string> widths;
};
std::optional<LoadedPage> LoadInChromium(const fs::path& html, const fs::path& profile) {
  const std::string chromium = Chromium();
  if (chromium.empty()) return std::nullopt;
  const Result dom = Shell("timeout 120 " + chromium +
                           " --headless --no-sandbox --disable-gpu --no-first-run --disable-background-networking"
                           " --user-data-dir=" + profile.string() +
                           " --virtual-time-budget=5000 --dump-dom file://" + html.string() + " 2>/dev/null");
  EXPECT_EQ(dom.code, 0) << dom.output.substr(0, 2000);
  LoadedPage page;
  std::smatch m;
  if (std::regex_search(dom.output, m, std::regex("data-images-loaded=\"(\\d+)\"")))
    page.images_loaded = m[1];
  else
    ADD_FAILURE() << "no data-images-loaded in " << dom.output.substr(0, 2000);
  const std::regex w("alt=\"([^\"]*)\"[^>]*data-natural-width=\"(\\d+)\"");
  for (auto it = std::sregex_iterator(dom.output.begin(), dom.output.end(), w); it != std::sregex_iterator(); ++it)
    page.widths.push_back((*it)[1].str() + "=" + (*it)[2].str());
  return page;
}

long CountMatches(const std::string& text, const std::string& re) {
  const std::regex r(re);
  return std::distance(std::sregex_iterator(text.begin(), text.end(), r), std::sregex_iterator());
}

TEST(ReportHtml, ChromiumLoadsEveryImage) {
  Dir tmp("chromium");
  const fs::path data = tmp.path / "data", run = tmp.path / "run";
  MakeRunFolder(data, run);
  const Result r = Cli("-q report --run " + run.string() + " --gt " + (data / "gt_mesh.ply").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const std::string html = ReadFile(run / "report.html");
  // Self-contained: images are data URIs, no file links.
  EXPECT_EQ(CountMatches(html, "<img "), 3);  // turntable, depth, edges
  EXPECT_EQ(CountMatches(html, "<img src=\"data:image/png;base64,"), 3);
  // Figures from report.json and the evaluation of the ground truth against itself.
  EXPECT_NE(html.find("<td>depth_sparse</td><td>12.50</td><td>50.0 %</td>"), std::string::npos);
  EXPECT_NE(html.find("Peak memory (RSS) 300 MiB"), std::string::npos);
  EXPECT_NE(html.find("<td>5 mm</td><td>1.000</td><td>1.000</td><td>1.000</td>"), std::string::npos);
  EXPECT_TRUE(fs::exists(run / "eval.json"));

  const auto page = LoadInChromium(run / "report.html", tmp.path / "profile");
  if (!page) GTEST_SKIP() << "chromium is not installed (deploy/install_deps.sh installs Debian's chromium)";
  EXPECT_EQ(page->images_loaded, "3");
  // The turntable stand-in and the depth figure are the depth command's preview (frame | map
  // side by side: 192 px), the edge preview 96 px.
  EXPECT_EQ(page->widths,
            (std::vector<std::string>{"turntable render of mesh.ply=192", "depth 00030=192", "edges 00030=96"}));
  // Without preview/, the depth figure is made from depth/00030.pfm (the map alone: 96 px).
  fs::remove_all(run / "preview");
  ASSERT_EQ(Cli("-q report --run " + run.string()).code, 0);
  const auto from_pfm = LoadInChromium(run / "report.html", tmp.path / "profile");
  ASSERT_TRUE(from_pfm);
  EXPECT_EQ(from_pfm->images_loaded, "3");
  EXPECT_EQ(from_pfm->widths,
            (std::vector<std::string>{"turntable render of mesh.ply=192", "depth 00030=96", "edges 00030=96"}));
}

// `lfrecon run`'s own report.html: beside the turntable, the depth and edge
// previews of --previews views evenly spread over those processed (views
// 0, 3, ..., 87: the 0th, 10th and 20th of 30 at --previews 3), each loaded.
TEST(ReportHtml, RunShowsDepthAndEdgePreviews) {
  Dir tmp("run");
  const fs::path data = tmp.path / "data", run = tmp.path / "run";
  ASSERT_EQ(Cli("-q synth --scene sphere --frames 90 --width 96 --height 54 --out " + data.string()).code, 0);
  const Result r = Cli("-q run --dataset " + data.string() + " --out " + run.string() +
                       " --no-refine-poses --voxel-mm 4 --views 0:90:3 --previews 3");
  ASSERT_EQ(r.code, 0) << r.output;
  const std::vector<std::string> stems = {"00000", "00030", "00060"};
  for (const char* dir : {"preview", "edges"}) {
    std::vector<std::string> written;
    for (const auto& e : fs::directory_iterator(run / dir)) written.push_back(e.path().stem().string());
    std::sort(written.begin(), written.end());
    EXPECT_EQ(written, stems) << dir;
  }
  const std::string html = ReadFile(run / "report.html");
  EXPECT_EQ(CountMatches(html, "<img src=\"data:image/png;base64,"), 7);  // turntable, 3 depth, 3 edges
  EXPECT_EQ(CountMatches(html, "alt=\"edges 000(00|30|60)\""), 3);
  EXPECT_EQ(CountMatches(html, "alt=\"depth 000(00|30|60)\""), 3);
  const auto page = LoadInChromium(run / "report.html", tmp.path / "profile");
  if (!page) GTEST_SKIP() << "chromium is not installed (deploy/install_deps.sh installs Debian's chromium)";
  EXPECT_EQ(page->images_loaded, "7");
  std::vector<std::string> expected = {"turntable render of mesh.ply=" +
                                       std::to_string(PngWidth(run / "mesh_turntable.png"))};
  for (const std::string& s : stems) {
    expected.push_back("depth " + s + "=192");  // frame | fused depth
    expected.push_back("edges " + s + "=96");
  }
  EXPECT_EQ(page->widths, expected);
}

TEST(ReportHtml, MissingReportJsonNamesIt) {
  Dir tmp("missing");
  const Result r = Cli("report --run " + tmp.path.string());
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.output.find("report.json"), std::string::npos) << r.output;
}

TEST(RunExports, UnknownMeshFormatIsAUsageError) {
  Dir tmp("format");
  const Result r = Cli("run --dataset " + tmp.path.string() + " --out " + (tmp.path / "o").string() +
                       " --mesh-format ply,stl");
  EXPECT_EQ(r.code, 2) << r.output;
  EXPECT_NE(r.output.find("--mesh-format"), std::string::npos) << r.output;
}

// "element NAME N" of a PLY header.
long PlyCount(const fs::path& p, const std::string& element) {
  const std::string b = ReadFile(p);
  const std::smatch none;
  std::smatch m;
  const std::string header = b.substr(0, b.find("end_header"));
  if (!std::regex_search(header, m, std::regex("element " + element + " (\\d+)"))) return -1;
  return std::stol(m[1]);
}

long CountLines(const std::string& text, const std::string& prefix) {
  long n = 0;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) n += line.rfind(prefix, 0) == 0;
  return n;
}

// A small run with every export: mesh.obj/glb with mesh.ply's counts, points.ply,
// and a COLMAP workspace that COLMAP's own stereo_fusion fuses (when colmap is installed).
TEST(RunExports, FilesOtherToolsOpen) {
  Dir tmp("exports");
  const fs::path data = tmp.path / "data", run = tmp.path / "run";
  ASSERT_EQ(Cli("-q synth --scene sphere --frames 90 --width 96 --height 54 --out " + data.string()).code, 0);
  const Result r = Cli("-q run --dataset " + data.string() + " --out " + run.string() +
                       " --no-refine-poses --no-refine --voxel-mm 4 --views 0:90:3 --mesh-format ply,obj,glb"
                       " --point-cloud --export-depth-colmap");
  ASSERT_EQ(r.code, 0) << r.output;
  const long vertices = PlyCount(run / "mesh.ply", "vertex"), faces = PlyCount(run / "mesh.ply", "face");
  ASSERT_GT(faces, 1000);
  const std::string obj = ReadFile(run / "mesh.obj");
  EXPECT_EQ(CountLines(obj, "v "), vertices);
  EXPECT_EQ(CountLines(obj, "f "), faces);
  EXPECT_EQ(ReadFile(run / "mesh.glb").substr(0, 4), "glTF");
  EXPECT_GT(PlyCount(run / "points.ply", "vertex"), 1000);
  long maps = 0;
  for (const auto& e : fs::directory_iterator(run / "colmap" / "stereo" / "depth_maps")) {
    ++maps;
    EXPECT_EQ(ReadFile(e.path()).substr(0, 8), "96&54&1&") << e.path();
  }
  EXPECT_EQ(maps, 30);
  EXPECT_TRUE(fs::exists(run / "report.html"));
  if (!fs::exists("/usr/bin/colmap")) GTEST_SKIP() << "colmap is not installed: its stereo_fusion is not tried";
  const Result fused = Shell("colmap stereo_fusion --workspace_path " + (run / "colmap").string() +
                             " --input_type geometric --output_path " + (tmp.path / "fused.ply").string());
  ASSERT_EQ(fused.code, 0) << fused.output;
  // COLMAP fuses only pixels whose depth and normal agree in 5 views (10 degrees): tens to
  // hundreds of these 96x54 maps (the maps as fused, after the geometric consistency check
  // that every neighbour must pass: 70 measured; 360 without the check); 0 when poses,
  // names or the layout are wrong.
  EXPECT_GT(PlyCount(tmp.path / "fused.ply", "vertex"), 20) << fused.output.substr(fused.output.size() > 2000 ? fused.output.size() - 2000 : 0);
}

}  // namespace
