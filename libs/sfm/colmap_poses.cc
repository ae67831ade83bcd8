#include "sfm/colmap_poses.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <fstream>
#include <iomanip>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>
#include <set>
#include <sstream>

#include "io/colmap_model.h"
#include "io/frame_source.h"
#include "sfm/subprocess.h"
#include "util/error.h"
#include "util/path.h"
#include "util/progress.h"

namespace lfrecon {
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

bool IsImageName(const fs::path& p) {
  const std::string ext = LowerExtension(p);
  return ext == ".png" || ext == ".jpg" || ext == ".jpeg" || ext == ".tif" || ext == ".tiff" || ext == ".bmp";
}

void WriteLines(const fs::path& path, const std::vector<std::string>& lines) {
  std::ofstream out(path);
  for (const std::string& l : lines) out << l << "\n";
  out.close();
  if (!out) throw InputError(path.string(), "cannot write");
}

// COLMAP's progress lines (logged at info, at most every few seconds); the rest at debug.
bool IsProgressLine(const std::string& line) {
  static const char* kPrefixes[] = {"Processed file", "Matching image", "Matching block", "Registering image",
                                    "Bundle adjustment report", "Elapsed time"};
  for (const char* p : kPrefixes)
    if (line.rfind(p, 0) == 0) return true;
  return false;
}

class ColmapRunner {
 public:
  ColmapRunner(std::string binary, fs::path workspace) : binary_(std::move(binary)), ws_(std::move(workspace)) {}

  // Runs `colmap <command> args...`; throws ExternalToolError on failure.
  double Run(const std::string& command, std::vector<std::string> args) {
    std::vector<std::string> argv = {binary_, command};
    argv.insert(argv.end(), args.begin(), args.end());
    // glog to stderr (we capture it) instead of log files in /tmp.
    argv.push_back("--log_to_stderr");
    argv.push_back("1");
    const fs::path log_path = ws_ / "logs" / (std::to_string(++count_) + "_" + command + ".log");
    fs::create_directories(log_path.parent_path());
    std::ofstream log(log_path);
    for (const std::string& a : argv) log << a << " ";
    log << "\n";
    SubprocessOptions so;
    so.working_dir = ws_;
    so.keep_lines = 12;
    auto last_info = std::chrono::steady_clock::now() - std::chrono::seconds(10);
    so.on_line = [&](const std::string& line, bool) {
      log << line << "\n";
      if (line.empty()) return;
      const auto now = std::chrono::steady_clock::now();
      if (IsProgressLine(line) && (now - last_info > std::chrono::seconds(3) || line.rfind("Elapsed", 0) == 0)) {
        spdlog::info("colmap {}: {}", command, line);
        last_info = now;
      } else {
        spdlog::debug("colmap {}: {}", command, line);
      }
    };
    spdlog::info("poses: colmap {}", command);
    SubprocessResult r;
    try {
      r = RunSubprocess(argv, so);
    } catch (const ExternalToolError& e) {
      throw ExternalToolError("COLMAP: " + std::string(e.what()) +
                              "; install Debian's colmap package (apt-get install colmap, or "
                              "deploy/install_deps.sh) or pass --colmap PATH");
    }
    if (r.exit_status != 0) {
      std::string tail;
      for (const std::string& l : r.last_lines) tail += "\n  " + l;
      throw ExternalToolError(binary_ + " " + command + " failed (" +
                              (r.signaled ? "killed by signal " + std::to_string(r.exit_status - 128)
                                          : "exit status " + std::to_string(r.exit_status)) +
                              "); last output lines:" + tail + "\n(whole log: " + log_path.string() + ")");
    }
    return r.seconds;
  }

 private:
  std::string binary_;
  fs::path ws_;
  int count_ = 0;
};

// The model folder under `dir` (COLMAP's mapper writes dir/0, dir/1, ...) with the most images.
fs::path LargestModel(const fs::path& dir, int* num_images) {
  fs::path best;
  *num_images = 0;
  if (!fs::is_directory(dir)) return best;
  for (const auto& entry : fs::directory_iterator(dir)) {
    if (!entry.is_directory() || FindColmapModel(entry.path()).empty()) continue;
    const ColmapModel m = ReadColmapModel(entry.path());
    if (static_cast<int>(m.images.size()) > *num_images) {
      *num_images = static_cast<int>(m.images.size());
      best = entry.path();
    }
  }
  return best;
}

std::string ThreadsArg(int threads) { return std::to_string(threads > 0 ? threads : -1); }

}  // namespace

int KeyframeStep(int frames, int max_keyframes) {
  if (frames <= 0 || max_keyframes <= 0) return 3;
  return std::max(3, (frames + max_keyframes - 1) / max_keyframes);
}

void ColmapPosesOptions::Check() const {
  if (video_path.empty() == images_dir.empty()) throw OptionError("poses: give exactly one of --video and --images");
  if (out_dir.empty()) throw OptionError("poses: --out is required");
  if (step < 0) throw OptionError("poses: --step must be >= 0 (0: automatic)");
  if (max_keyframes < 3) throw OptionError("poses: --max-keyframes must be >= 3");
  if (max_frames < 0) throw OptionError("poses: --max-frames must be >= 0");
  if (camera_model != "SIMPLE_RADIAL" && camera_model != "PINHOLE")
    throw OptionError("poses: --camera-model must be SIMPLE_RADIAL or PINHOLE");
  if (threads < 0) throw OptionError("poses: --threads must be >= 0");
  if (max_num_features < 100) throw OptionError("poses: --max-features must be >= 100");
  if (overlap < 1) throw OptionError("poses: --overlap must be >= 1");
  if (loop_pairs < 0) throw OptionError("poses: --loop-pairs must be >= 0");
  if (register_neighbours < 1) throw OptionError("poses: --register-neighbours must be >= 1");
  if (image_format != "png" && image_format != "jpg") throw OptionError("poses: --format must be png or jpg");
  if (colmap.empty()) throw OptionError("poses: --colmap must name a binary");
  world.Check();
}

ColmapPosesSummary EstimatePosesWithColmap(const ColmapPosesOptions& options) {
  options.Check();
  Timer total;
  ColmapPosesSummary summary;
  // Fail before the slow part when COLMAP is not there.
  if (FindExecutable(options.colmap).empty()) {
    throw ExternalToolError("COLMAP: '" + options.colmap + "' not found" +
                            (options.colmap.find('/') == std::string::npos ? " on PATH" : "") +
                            "; install Debian's colmap package (apt-get install colmap, or deploy/install_deps.sh) "
                            "or pass --colmap PATH");
  }
  // Absolute: COLMAP runs in OUT/colmap, where a relative --out would not resolve.
  const fs::path out = fs::absolute(options.out_dir);
  const fs::path images = out / "images";
  const fs::path ws = out / "colmap";
  fs::create_directories(images);
  fs::remove_all(ws);
  fs::create_directories(ws);

  // 1. Frames into OUT/images.
  Timer t;
  std::vector<std::string> names;
  if (!options.video_path.empty()) {
    cv::VideoCapture cap(options.video_path.string(), cv::CAP_FFMPEG);
    if (!cap.isOpened()) cap.open(options.video_path.string(), cv::CAP_ANY);
    if (!cap.isOpened()) throw InputError(options.video_path.string(), "cannot open as a video (OpenCV VideoCapture)");
    const int count = static_cast<int>(cap.get(cv::CAP_PROP_FRAME_COUNT));
    Progress progress("poses: frames from " + options.video_path.filename().string(),
                      options.max_frames > 0 && count > 0 ? std::min(count, options.max_frames) : count);
    cv::Mat frame;
    const std::vector<int> params =
        options.image_format == "jpg" ? std::vector<int>{cv::IMWRITE_JPEG_QUALITY, 95} : std::vector<int>{};
    while ((options.max_frames == 0 || static_cast<int>(names.size()) < options.max_frames) && cap.read(frame)) {
      char name[32];
      std::snprintf(name, sizeof(name), "frame_%05d.%s", static_cast<int>(names.size()), options.image_format.c_str());
      if (!cv::imwrite((images / name).string(), frame, params))
        throw InputError((images / name).string(), "cannot write the frame");
      names.push_back(name);
      progress.Advance();
    }
    progress.Finish();
    if (names.empty()) throw InputError(options.video_path.string(), "no frame could be decoded");
  } else {
    if (!fs::is_directory(options.images_dir)) throw InputError(options.images_dir.string(), "not a folder");
    for (const auto& entry : fs::directory_iterator(options.images_dir))
      if (entry.is_regular_file() && IsImageName(entry.path())) names.push_back(entry.path().filename().string());
    std::sort(names.begin(), names.end(), NaturalNameLess);
    if (options.max_frames > 0 && static_cast<int>(names.size()) > options.max_frames) names.resize(options.max_frames);
    if (names.empty()) throw InputError(options.images_dir.string(), "no image files (png, jpg, tif, bmp)");
    std::error_code ec;
    const bool same = fs::equivalent(options.images_dir, images, ec);
    if (!same) {
      for (const std::string& n : names) {
        const fs::path dst = images / n;
        fs::remove(dst);
        std::error_code link_ec;
        fs::create_hard_link(options.images_dir / n, dst, link_ec);
        if (link_ec) fs::copy_file(options.images_dir / n, dst, fs::copy_options::overwrite_existing);
      }
    }
  }
  summary.frames = static_cast<int>(names.size());
  summary.step_seconds.emplace_back("frames", t.Seconds());
  if (summary.frames < 3) throw InputError(options.video_path.empty() ? options.images_dir.string() : options.video_path.string(),
                                           "fewer than 3 frames");

  // 2. Keyframes: every step-th frame and the last one.
  summary.step = options.step > 0 ? options.step : KeyframeStep(summary.frames, options.max_keyframes);
  std::vector<int> key_index;
  for (int i = 0; i < summary.frames; i += summary.step) key_index.push_back(i);
  if (key_index.back() != summary.frames - 1) key_index.push_back(summary.frames - 1);
  std::vector<std::string> key_names, rest_names;
  std::vector<bool> is_key(summary.frames, false);
  for (int i : key_index) is_key[i] = true;
  for (int i = 0; i < summary.frames; ++i) (is_key[i] ? key_names : rest_names).push_back(names[i]);
  summary.keyframes = static_cast<int>(key_names.size());
  spdlog::info("poses: {} frames, {} keyframes (every {}), {} to register", summary.frames, summary.keyframes,
               summary.step, rest_names.size());
  WriteLines(ws / "keyframes.txt", key_names);
  WriteLines(ws / "others.txt", rest_names);

  ColmapRunner colmap(options.colmap, ws);
  const std::string db = (ws / "database.db").string();
  const std::string threads = ThreadsArg(options.threads);
  const std::vector<std::string> sift = {"--SiftExtraction.use_gpu", "0", "--SiftExtraction.num_threads", threads,
                                         "--SiftExtraction.max_num_features", std::to_string(options.max_num_features)};
  const std::vector<std::string> matching = {"--SiftMatching.use_gpu", "0", "--SiftMatching.num_threads", threads};
  auto with = [](std::vector<std::string> a, const std::vector<std::string>& b) {
    a.insert(a.end(), b.begin(), b.end());
    return a;
  };

  // 3. SfM on the keyframes.
  summary.step_seconds.emplace_back(
      "feature_extractor (keyframes)",
      colmap.Run("feature_extractor", with({"--database_path", db, "--image_path", images.string(), "--image_list_path",
                                            (ws / "keyframes.txt").string(), "--ImageReader.single_camera", "1",
                                            "--ImageReader.camera_model", options.camera_model},
                                           sift)));
  summary.step_seconds.emplace_back(
      "sequential_matcher",
      colmap.Run("sequential_matcher",
                 with({"--database_path", db, "--SequentialMatching.overlap", std::to_string(options.overlap),
                       "--SequentialMatching.quadratic_overlap", "0", "--SequentialMatching.loop_detection", "0"},
                      matching)));
  const int loop = std::min(options.loop_pairs, summary.keyframes / 2);
  if (loop > 0 && summary.keyframes > 2 * options.overlap) {
    std::vector<std::string> pairs;
    for (int a = 0; a < loop; ++a)
      for (int b = summary.keyframes - loop; b < summary.keyframes; ++b)
        if (b - a > options.overlap) pairs.push_back(key_names[a] + " " + key_names[b]);
    if (!pairs.empty()) {
      WriteLines(ws / "loop_pairs.txt", pairs);
      summary.step_seconds.emplace_back(
          "matches_importer (loop closure)",
          colmap.Run("matches_importer", with({"--database_path", db, "--match_list_path",
                                               (ws / "loop_pairs.txt").string(), "--match_type", "pairs"},
                                              matching)));
    }
  }
  fs::create_directories(ws / "keyframe_model");
  summary.step_seconds.emplace_back(
      "mapper", colmap.Run("mapper", {"--database_path", db, "--image_path", images.string(), "--output_path",
                                      (ws / "keyframe_model").string(), "--Mapper.num_threads", threads}));
  const fs::path key_model = LargestModel(ws / "keyframe_model", &summary.keyframes_registered);
  if (key_model.empty())
    throw ExternalToolError(options.colmap + " mapper reconstructed no model from the " +
                            std::to_string(summary.keyframes) + " keyframes (too little texture or overlap? try a " +
                            "smaller --step); logs in " + (ws / "logs").string());
  spdlog::info("poses: keyframe model {} with {}/{} keyframes", key_model.filename().string(),
               summary.keyframes_registered, summary.keyframes);

  // 4. The other frames: same camera, matched with their nearest keyframes, registered.
  fs::path final_model = key_model;
  if (!rest_names.empty()) {
    summary.step_seconds.emplace_back(
        "feature_extractor (others)",
        colmap.Run("feature_extractor",
                   with({"--database_path", db, "--image_path", images.string(), "--image_list_path",
                         (ws / "others.txt").string(), "--ImageReader.existing_camera_id", "1"},
                        sift)));
    std::vector<std::string> pairs;
    for (int i = 0; i < summary.frames; ++i) {
      if (is_key[i]) continue;
      const int k = static_cast<int>(std::upper_bound(key_index.begin(), key_index.end(), i) - key_index.begin());
      // key_index[k-1] < i < key_index[k]
      for (int j = std::max(0, k - options.register_neighbours);
           j < std::min(static_cast<int>(key_index.size()), k + options.register_neighbours); ++j)
        pairs.push_back(names[i] + " " + names[key_index[j]]);
    }
    WriteLines(ws / "register_pairs.txt", pairs);
    summary.step_seconds.emplace_back(
        "matches_importer (others)",
        colmap.Run("matches_importer", with({"--database_path", db, "--match_list_path",
                                             (ws / "register_pairs.txt").string(), "--match_type", "pairs"},
                                            matching)));
    fs::create_directories(ws / "model");
    summary.step_seconds.emplace_back(
        "image_registrator",
        colmap.Run("image_registrator", {"--database_path", db, "--input_path", key_model.string(), "--output_path",
                                         (ws / "model").string(), "--Mapper.num_threads", threads}));
    final_model = ws / "model";
  }
  if (options.bundle_adjust_all) {
    fs::create_directories(ws / "model_ba");
    summary.step_seconds.emplace_back(
        "bundle_adjuster", colmap.Run("bundle_adjuster", {"--input_path", final_model.string(), "--output_path",
                                                          (ws / "model_ba").string()}));
    final_model = ws / "model_ba";
  }

  // 5. The normalised world, V, and the dataset's sparse/ and scene.json.
  t.Restart();
  ColmapModel model = ReadColmapModel(final_model);
  const std::vector<SparsePoint> points = ReadColmapPoints3D(final_model);
  std::set<std::string> posed;
  std::vector<Rigid3d> poses;
  std::vector<Camera> cameras;
  for (const ColmapImage& im : model.images) {
    posed.insert(im.name);
    poses.push_back(im.cam_from_world);
    cameras.push_back(model.cameras.at(im.camera_id));
  }
  for (const std::string& n : names)
    if (!posed.count(n)) summary.unregistered.push_back(n);
  summary.registered = static_cast<int>(model.images.size());
  summary.world = EstimateWorldFrame(poses, cameras, points, options.world, final_model.string());
  for (ColmapImage& im : model.images) im.cam_from_world = summary.world.sfm_to_world.TransformPose(im.cam_from_world);
  summary.camera = model.cameras.begin()->second;
  fs::remove_all(out / "sparse");
  WriteColmapModelText(model, out / "sparse");

  const Similarity3d& S = summary.world.sfm_to_world;
  json scene;
  scene["foreground_bbox_min"] = {summary.world.volume.min.x(), summary.world.volume.min.y(), summary.world.volume.min.z()};
  scene["foreground_bbox_max"] = {summary.world.volume.max.x(), summary.world.volume.max.y(), summary.world.volume.max.z()};
  scene["frames"] = summary.frames;
  scene["width"] = summary.camera.width;
  scene["height"] = summary.camera.height;
  scene["units"] =
      "SfM, no metric scale: nominal metres with the median camera distance from V's centre = " +
      std::to_string(options.world.camera_distance) + " (voxel size: use lfrecon run's default, V's longest side / 256)";
  scene["convention"] = "sparse/: COLMAP text, world-to-camera, OpenCV axes; world up = +z, origin at V's bottom centre";
  json sfm;
  sfm["tool"] = "lfrecon poses (COLMAP, " + options.camera_model + ", one camera)";
  sfm["step"] = summary.step;
  sfm["keyframes"] = summary.keyframes;
  sfm["keyframes_registered"] = summary.keyframes_registered;
  sfm["registered"] = summary.registered;
  sfm["unregistered"] = summary.unregistered;
  sfm["points_total"] = summary.world.points_total;
  sfm["points_in_volume"] = summary.world.points_in_volume;
  sfm["up_spread_deg"] = summary.world.up_spread_deg;
  sfm["up"] = summary.world.up_from_path ? "normal of the camera path's plane" : "cameras' mean up";
  sfm["colmap_model"] = fs::relative(final_model, out).string();
  sfm["world_from_colmap"] = {{"scale", S.scale},
                              {"rotation", {{S.rotation(0, 0), S.rotation(0, 1), S.rotation(0, 2)},
                                            {S.rotation(1, 0), S.rotation(1, 1), S.rotation(1, 2)},
                                            {S.rotation(2, 0), S.rotation(2, 1), S.rotation(2, 2)}}},
                              {"translation", {S.translation.x(), S.translation.y(), S.translation.z()}}};
  json steps = json::object();
  for (const auto& [name, s] : summary.step_seconds) steps[name] = s;
  sfm["seconds"] = steps;
  scene["sfm"] = sfm;
  {
    std::ofstream f(out / "scene.json");
    f << std::setw(1) << scene << "\n";
    f.close();
    if (!f) throw InputError((out / "scene.json").string(), "cannot write");
  }
  summary.step_seconds.emplace_back("world frame and output", t.Seconds());
  summary.seconds = total.Seconds();
  if (!summary.unregistered.empty())
    spdlog::warn("poses: {} of {} frames could not be registered (first: {}); the dataset has the other {}",
                 summary.unregistered.size(), summary.frames, summary.unregistered.front(), summary.registered);
  return summary;
}

}  // namespace lfrecon
