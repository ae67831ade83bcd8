#pragma once
// The synthetic job the integration tests share: a sphere, 90 frames of 96x54
// (`lfrecon synth`), in a fresh folder under the system temp dir; and, when
// asked, `lfrecon run`'s result on it (with the poses as given: the service does
// not refine poses) scored against the generator's mesh at 2 and 4 voxels.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstddef>
#include <filesystem>
#include <string>

#include "daemon_process.h"
#include "eval/mesh_metrics.h"
#include "io/dataset.h"
#include "io/ply.h"

namespace lfrecon::testing {

// The built executables (lfrecon, the daemons).
inline std::string BinDir() { return std::string(LFRECON_BINARY_DIR) + "/bin/"; }
inline const std::string kBin = BinDir();

constexpr double kReferenceVoxelMm = 8.0;  // the voxel of the reference run and of the tests' jobs

struct ReferenceDataset {
  std::filesystem::path dir;      // removed by RemoveReference
  std::filesystem::path dataset;  // dir/dataset
  int views = 0;
  BoundingBox volume;  // the dataset's bounding box
  TriangleMesh gt;     // gt_mesh.ply
  // With the run: lfrecon run's fused mesh (mesh_raw.ply, what the service
  // exports) and its refined mesh (mesh.ply, what export --refine gives).
  bool has_run = false;
  double f2 = 0, f4 = 0;  // F-score at 2 and 4 voxels of mesh_raw.ply
  std::size_t triangles = 0;
  double refined_f2 = 0, refined_f4 = 0;  // of mesh.ply
  std::size_t refined_triangles = 0;
};

// `mesh` against the reference's ground truth inside its volume: thresholds 2
// and 4 voxels, samples every half voxel.
inline MeshMetrics ScoreAgainstReference(const TriangleMesh& mesh, const ReferenceDataset& ref) {
  MeshMetricsOptions mo;
  mo.thresholds = {2 * kReferenceVoxelMm / 1000, 4 * kReferenceVoxelMm / 1000};
  mo.sample_spacing = kReferenceVoxelMm / 2000;
  mo.volume = ref.volume;
  return EvaluateMesh(mesh, ref.gt, nullptr, mo);
}

// Writes the dataset into temp/lfrecon_<tag>_<pid>/dataset and, with
// `with_run`, runs `lfrecon run --no-refine-poses` on it into .../run and
// scores both meshes. A failing command is a fatal failure of the caller
// (check HasFatalFailure()).
inline void MakeReference(const std::string& tag, bool with_run, ReferenceDataset* ref) {
  namespace fs = std::filesystem;
  *ref = ReferenceDataset{};
  ref->dir = fs::temp_directory_path() / ("lfrecon_" + tag + "_" + std::to_string(::getpid()));
  fs::remove_all(ref->dir);
  fs::create_directories(ref->dir);
  ref->dataset = ref->dir / "dataset";
  CommandResult r = RunShell(BinDir() + "lfrecon -q synth --scene sphere --frames 90 --width 96 --height 54 --out " +
                             ref->dataset.string());
  ASSERT_EQ(r.code, 0) << r.output;
  DatasetOptions d;
  d.dataset_dir = ref->dataset;
  const Dataset ds = Dataset::Open(d);
  ref->views = ds.NumViews();
  ref->volume = ds.bbox();
  ref->gt = ReadPly(ref->dataset / "gt_mesh.ply");
  if (!with_run) return;
  r = RunShell(BinDir() + "lfrecon -q run --dataset " + ref->dataset.string() + " --no-refine-poses --voxel-mm " +
               std::to_string(kReferenceVoxelMm) + " --out " + (ref->dir / "run").string());
  ASSERT_EQ(r.code, 0) << r.output;
  const TriangleMesh raw = ReadPly(ref->dir / "run" / "mesh_raw.ply");
  ref->triangles = raw.triangles.size();
  const MeshMetrics m = ScoreAgainstReference(raw, *ref);
  ref->f2 = m.scores[0].fscore;
  ref->f4 = m.scores[1].fscore;
  const TriangleMesh refined = ReadPly(ref->dir / "run" / "mesh.ply");
  ref->refined_triangles = refined.triangles.size();
  const MeshMetrics mr = ScoreAgainstReference(refined, *ref);
  ref->refined_f2 = mr.scores[0].fscore;
  ref->refined_f4 = mr.scores[1].fscore;
  ref->has_run = true;
}

inline void RemoveReference(const ReferenceDataset& ref) {
  std::error_code ec;
  if (!ref.dir.empty()) std::filesystem::remove_all(ref.dir, ec);
}

}  // namespace lfrecon::testing
