// Fusion (§5) of depth maps already on disk — e.g. `lfrecon run --write-depth`
// or `lfrecon depth --stage dense` output — for several values of σ_s, scored
// against the dataset's ground-truth mesh. Tunes fusion without re-running
// the depth stages (which take most of a run).
//
//   fusion_from_depth_bench DATASET DEPTH_OUT [--sigma-s 0.1,0.15,0.2] [--voxel-mm 2] [--prune-every 16] [--activation-min-confidence 0.05]
//
// DEPTH_OUT holds depth/<stem>.pfm and confidence/<stem>.pfm; labels are not
// stored, so a depth is foreground when its point lies inside V.
#include <spdlog/spdlog.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "eval/mesh_metrics.h"
#include "fusion/probabilistic_fusion.h"
#include "io/dataset.h"
#include "io/depth_map_io.h"
#include "io/ply.h"
#include "util/progress.h"

using namespace lfrecon;
namespace fs = std::filesystem;

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr,
                 "usage: %s DATASET DEPTH_OUT [--sigma-s a,b,...] [--voxel-mm MM] [--prune-every N] [--activation-min-confidence C] [--keep-mesh DIR]\n",
                 argv[0]);
    return 2;
  }
  const fs::path dataset_dir = argv[1], depth_dir = argv[2];
  std::vector<double> sigmas = {0.15};
  double voxel_mm = 0;
  int prune_every = 16;
  fs::path keep_dir;
  double min_conf = 0;
  for (int a = 3; a + 1 < argc; a += 2) {
    const std::string k = argv[a], v = argv[a + 1];
    if (k == "--sigma-s") {
      sigmas.clear();
      std::stringstream ss(v);
      std::string item;
      while (std::getline(ss, item, ',')) sigmas.push_back(std::atof(item.c_str()));
    } else if (k == "--voxel-mm") {
      voxel_mm = std::atof(v.c_str());
    } else if (k == "--prune-every") {
      prune_every = std::atoi(v.c_str());
    } else if (k == "--activation-min-confidence") {
      min_conf = std::atof(v.c_str());
    } else if (k == "--keep-mesh") {
      keep_dir = v;
    } else {
      std::fprintf(stderr, "unknown option %s\n", k.c_str());
      return 2;
    }
  }
  DatasetOptions dopt;
  dopt.dataset_dir = dataset_dir;
  const Dataset ds = Dataset::Open(dopt);
  const auto gt_path = ds.GroundTruthMeshPath(false);
  if (!gt_path) {
    std::fprintf(stderr, "%s has no ground-truth mesh\n", dataset_dir.c_str());
    return 1;
  }
  const TriangleMesh gt = ReadPly(*gt_path);
  const auto thin_path = ds.GroundTruthMeshPath(true);
  TriangleMesh thin;
  if (thin_path) thin = ReadPly(*thin_path);
  // Maps present on disk, by image stem.
  std::vector<int> ids;
  std::vector<DepthMap> maps;
  for (int i = 0; i < ds.NumViews(); ++i) {
    const std::string stem = fs::path(ds.views()[i].name).stem().string();
    const fs::path d = depth_dir / "depth" / (stem + ".pfm"), c = depth_dir / "confidence" / (stem + ".pfm");
    if (!fs::exists(d)) continue;
    DepthMap m;
    m.depth = ReadPfm(d);
    if (fs::exists(c)) m.confidence = ReadPfm(c);
    ids.push_back(i);
    maps.push_back(std::move(m));
  }
  std::printf("%zu depth maps from %s\n", maps.size(), depth_dir.c_str());
  if (maps.empty()) return 1;
  const double voxel = voxel_mm > 0 ? voxel_mm / 1000 : ds.bbox().Extent().maxCoeff() / 256;
  std::printf("voxel %.3f mm, prune every %d, activation min confidence %.3f\n", voxel * 1000, prune_every, min_conf);
  std::printf("sigma_s  F@2    F@5    F@10   P@5    R@5    thin@5  triangles  active  fuse_s\n");
  for (double s : sigmas) {
    FusionOptions fo;
    fo.volume = ds.bbox();
    fo.voxel_size = voxel;
    fo.sigma_s = s;
    fo.prune_every = prune_every;
    fo.activation_min_confidence = min_conf;
    ProbabilisticFusion fusion(fo);
    Timer t;
    for (std::size_t k = 0; k < maps.size(); ++k) fusion.Integrate(ds.View(ids[k]), maps[k], ids[k]);
    const double fuse_s = t.Seconds();
    const TriangleMesh mesh = fusion.ExtractMesh();
    MeshMetricsOptions mo;
    mo.thresholds = {0.002, 0.005, 0.010};
    mo.volume = ds.bbox();
    const MeshMetrics m = EvaluateMesh(mesh, gt, thin_path ? &thin : nullptr, mo);
    std::printf("%-7.3f  %.3f  %.3f  %.3f  %.3f  %.3f  %.3f   %9zu  %7zu  %6.1f\n", s, m.scores[0].fscore,
                m.scores[1].fscore, m.scores[2].fscore, m.scores[1].precision, m.scores[1].recall,
                m.scores[1].thin_recall, mesh.triangles.size(), fusion.Stats().active_voxels, fuse_s);
    std::fflush(stdout);
    if (!keep_dir.empty()) {
      fs::create_directories(keep_dir);
      char name[64];
      std::snprintf(name, sizeof(name), "fused_sigma_%.3f.ply", s);
      WritePly(mesh, keep_dir / name);
    }
  }
  return 0;
}
