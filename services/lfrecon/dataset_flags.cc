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
  app->add_option("--masks", options.masks_dir,
                  "Foreground mask folder (NAME.png, STEM.png or NAME per image, 255 = object; default DATASET/masks/). "
                  "A Nerfstudio frame's mask_path comes first, a PNG alpha channel last. Without --bbox or "
                  "scene.json, V is the masks' visual hull");
  app->add_option("--max-image-size", options.max_image_size,
                  "Downscale frames on read (INTER_AREA) so that their longer side is at most N pixels; "
                  "cameras scaled with them (0: as stored)");
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

std::vector<int> ParseViewRange(const std::string& spec, int n) {
  std::vector<int> out;
  if (spec.empty()) {
    for (int i = 0; i < n; ++i) out.push_back(i);
    return out;
  }
  int a = 0, b = n, step = 1;
  try {
    const auto c1 = spec.find(':');
    if (c1 == std::string::npos) {
      a = std::stoi(spec);
      b = a + 1;
    } else {
      if (c1 > 0) a = std::stoi(spec.substr(0, c1));
      const auto c2 = spec.find(':', c1 + 1);
      const std::string bs = spec.substr(c1 + 1, c2 == std::string::npos ? std::string::npos : c2 - c1 - 1);
      if (!bs.empty()) b = std::stoi(bs);
      if (c2 != std::string::npos) step = std::stoi(spec.substr(c2 + 1));
    }
  } catch (const std::exception&) {
    throw OptionError("--views: expected A:B:STEP, got '" + spec + "'");
  }
  if (step <= 0 || a < 0 || a >= n || b <= a)
    throw OptionError("--views " + spec + ": need 0 <= A < " + std::to_string(n) + ", B > A, STEP > 0");
  for (int i = a; i < std::min(b, n); i += step) out.push_back(i);
  return out;
}

}  // namespace lfrecon::cli
