#include "dataset_flags.h"

#include "util/error.h"

namespace lfrecon::cli {

void DatasetFlags::AddTo(CLI::App* app) {
  app->add_option("--dataset", options.dataset_dir,
                  "Dataset folder (images/ + sparse/ or transforms.json, optional scene.json)");
  app->add_option("--images", options.images_dir, "Image folder (with --colmap or --transforms)");
  app->add_option("--video", options.video_path, "Video file (with --colmap or --transforms)");
  app->add_option("--colmap", options.colmap_dir, "COLMAP sparse model folder (text or binary)");
  app->add_option("--transforms", options.transforms_path, "NeRF-style transforms.json");
  app->add_option("--bbox", bbox, "Foreground volume V: xmin ymin zmin xmax ymax zmax (metres)")->expected(6);
}

DatasetOptions DatasetFlags::Resolve() const {
  DatasetOptions out = options;
  if (!bbox.empty()) {
    BoundingBox b;
    b.min = Eigen::Vector3d(bbox[0], bbox[1], bbox[2]);
    b.max = Eigen::Vector3d(bbox[3], bbox[4], bbox[5]);
    if (!b.IsValid()) throw OptionError("--bbox: each max must be greater than its min");
    out.bbox = b;
  }
  out.Check();
  return out;
}

}  // namespace lfrecon::cli
