#pragma once
// The job store: one folder per job under a root that every daemon of a stack
// can read (one host, or a shared volume). It is the durable state of a job, so
// any daemon can restart and resume from it:
//   JOB/manifest.pb          JobManifest (cameras, V, options), written by ingest
//   JOB/frames/NNNNNN.pb     Frame: the image as received (JPEG/PNG bytes as on disk or as pushed,
//                            a video or raw frame as 8-bit lossless PNG), downscaled and undistorted
//                            on read (ingest; StoreFrameEncoder, FrameFromProto), and its object
//                            mask when the dataset has masks (PNG of the frame as read; MaskFromProto)
//   JOB/stream.pb            StreamOpen of a client-pushed job (ingest); manifest.pb follows at its end
//   JOB/ingest.done          frame count, when ingest has spooled every frame
//   JOB/sparse/NNNNNN.pb     DepthMap, sparse (§3.1) (aggregator, from depth workers)
//   JOB/dense/NNNNNN.pb      DepthMap, dense (§4) or filtered (aggregator, from propagate workers)
//   JOB/fused.log            view ids in the order they were fused (the fusion checkpoint)
//   JOB/status.pb            JobStatus once the job has ended (done, failed, cancelled)
//   JOB/cancelled            marker: ingest stops spooling
//   JOB/mesh.ply, mesh_raw.ply, grid.vdb   final outputs
//   JOB/mesh_refined.ply     refined mesh, written by the first `export --refine` of a finished job
// Every file is written to a temporary name and renamed, so a reader (or a
// restart after kill -9) never sees half a file.
#include <filesystem>
#include <memory>
#include <optional>
#include <string>

#include "depth/depth_map.h"
#include "geometry/pinhole_view.h"
#include "geometry/triangle_mesh.h"
#include "io/dataset.h"
#include "lfrecon_service.pb.h"
#include "pipeline/embedded_pipeline.h"
#include "pipeline/pipeline_flags.h"
#include "pipeline/reconstruction_plan.h"

namespace lfrecon::svc {

namespace pb = ::lfrecon::v1;

class JobStore {
 public:
  explicit JobStore(std::filesystem::path root);
  const std::filesystem::path& root() const { return root_; }

  // A new unique id ("j" + time + random hex); creates its folder.
  std::string CreateJob();
  // Ids are [A-Za-z0-9_-], 1..64 characters (never a path); false otherwise.
  static bool ValidJobId(const std::string& id);
  bool Exists(const std::string& id) const;
  std::filesystem::path JobDir(const std::string& id) const;  // throws std::invalid_argument for an invalid id

  void WriteManifest(const pb::JobManifest& manifest) const;
  pb::JobManifest ReadManifest(const std::string& id) const;  // throws InputError naming the file

  std::filesystem::path FramePath(const std::string& id, int index) const;
  std::filesystem::path MapPath(const std::string& id, pb::MapKind kind, int view) const;
  bool HasFrame(const std::string& id, int index) const { return std::filesystem::exists(FramePath(id, index)); }
  bool HasMap(const std::string& id, pb::MapKind kind, int view) const {
    return std::filesystem::exists(MapPath(id, kind, view));
  }
  void WriteFrame(const std::string& id, const pb::Frame& frame) const;
  // CV_32FC3 BGR in [0, 1]; checked against the manifest camera's size.
  cv::Mat ReadFrame(const std::string& id, int index, const PinholeView& expect) const;
  // The object mask stored with frame `index` (MaskFromProto: CV_8U of the
  // camera's size, nonzero = the object); an empty Mat when the frame has none.
  cv::Mat ReadMask(const std::string& id, int index, const PinholeView& expect) const;
  void WriteMap(const std::string& id, const pb::DepthMap& map) const;
  // `own` (may be null): the map's own-depth mask (pb::DepthMap.own; empty when it has none).
  DepthMap ReadMap(const std::string& id, pb::MapKind kind, int view, const PinholeView& expect,
                   cv::Mat* own = nullptr) const;

  // Small marker/state files.
  void WriteText(const std::string& id, const std::string& name, const std::string& text) const;
  std::optional<std::string> ReadText(const std::string& id, const std::string& name) const;
  void AppendLine(const std::string& id, const std::string& name, const std::string& line) const;

 private:
  std::filesystem::path root_;
};

// Writes `bytes` to `path` atomically and durably: a temporary file, fsync,
// rename, fsync of the folder, so a restart (even after a power loss) sees the
// whole file or the old one. On failure (a full disk) the temporary file is
// removed and InputError names the file and the system's reason.
void WriteFileAtomic(const std::filesystem::path& path, const std::string& bytes);
// A temporary name beside `path`, and its commit: fsync, rename onto `path`,
// fsync of the folder (the temporary file is removed on failure). For files
// written by other code (meshes): write to TempPathFor(path), then CommitFile.
std::filesystem::path TempPathFor(const std::filesystem::path& path);
void CommitFile(const std::filesystem::path& tmp, const std::filesystem::path& path);
std::string ReadFileBytes(const std::filesystem::path& path);  // throws InputError

// An exclusive flock(2) on `file` (created if missing) or on a folder, for the
// object's lifetime (the kernel drops it when the process dies, kill -9
// included). Throws std::runtime_error naming it if another process holds it.
class FileLock {
 public:
  explicit FileLock(const std::filesystem::path& file);
  ~FileLock();
  FileLock(const FileLock&) = delete;
  FileLock& operator=(const FileLock&) = delete;

 private:
  int fd_ = -1;
};

// One lfrecon-ingest per job store: an exclusive FileLock on STORE/.ingest.lock
// (the aggregator's lock is on the store folder itself, so the two daemons do
// not exclude each other; the name is not a job id, so no daemon takes it for
// a job). Throws std::runtime_error naming the store when another ingest holds it.
constexpr const char* kIngestLockName = ".ingest.lock";
std::unique_ptr<FileLock> LockStoreForIngest(const JobStore& store);

// True for a name TempPathFor gives: "<name>.tmp<pid>_<n>".
bool IsTempFileName(const std::string& name);
// What a writer killed mid-write (kill -9 between creating its temporary file
// and renaming it) leaves: removes, in every job of the store, the temporary
// files of the files ingest writes (manifest.pb, ingest.done, frames/*).
// Call with the ingest lock held (no other ingest is writing them). Returns
// how many were removed.
int RemoveIngestTempFiles(const JobStore& store);

// Conversions between the messages and the library types (all validate sizes
// and finiteness and throw InputError with `what` naming the source).
pb::Camera CameraToProto(const PinholeView& view, const std::string& name);
PinholeView CameraFromProto(const pb::Camera& camera, const std::string& what);
pb::Box BoxToProto(const BoundingBox& box);
BoundingBox BoxFromProto(const pb::Box& box, const std::string& what);
// A CV_32FC3 frame as read: 8-bit lossless PNG when it is exactly an 8-bit image
// (CompactFrame), else "f32-bgr".
pb::Frame FrameToProto(int index, const cv::Mat& image, const pb::Camera& camera);
// The frame as read (CV_32FC3 BGR in [0, 1], width x height): decoded (image
// headers checked against the stored size before decoding), then downscaled and
// undistorted when the frame has a source camera (PrepareFrame), so the pixels
// equal what io/Dataset hands `lfrecon run` for the same file.
cv::Mat FrameFromProto(const pb::Frame& frame, int width, int height, const std::string& what);
// The frame's object mask (Frame.mask): an empty Mat when it has none, else
// CV_8U width x height, nonzero = the object. The PNG header is checked
// against the size before any pixel is decoded; anything else (another format,
// size or pixel type, bytes that do not decode) throws InputError naming
// `what` (the frame) and its mask.
cv::Mat MaskFromProto(const pb::Frame& frame, int width, int height, const std::string& what);
// Frame.mask for `mask` (CV_8U, as io/Dataset's ReadMask gives it): lossless 8-bit PNG.
std::string MaskToPng(const cv::Mat& mask, const std::string& what);
// A client's raw frame ("bgr8", "f32-bgr") as the store keeps it ("png" when
// 8-bit, "f32-bgr" otherwise); others unchanged. Throws InputError on a size mismatch.
pb::Frame CompactFrameProto(pb::Frame frame, const std::string& what);
pb::SourceCamera SourceCameraToProto(const Camera& camera, int stored_width, int stored_height);
// Throws InputError naming `what` (unknown model, parameter count, sizes).
Camera SourceCameraFromProto(const pb::SourceCamera& source, const std::string& what);

// The frames of a dataset as the job store keeps them: an image file's bytes
// as on disk (PNG, JPEG), a video frame as 8-bit lossless PNG, each with its
// source camera (downscale and undistortion happen on read); images of other
// formats (TIFF, EXR, BMP) are read through the dataset and stored as
// FrameToProto does. When the dataset has masks, each frame carries its mask as
// `lfrecon run` reads it (Dataset::ReadMask, MaskToPng). Used by ingest's
// submit path and by `lfrecon stream`.
class StoreFrameEncoder {
 public:
  explicit StoreFrameEncoder(const Dataset& dataset);
  ~StoreFrameEncoder();
  // Frame k. `validate`: decoded once (a corrupt file throws InputError naming it).
  pb::Frame Encode(int k, bool validate);

 private:
  pb::Frame EncodeImage(int k, bool validate);  // the frame without its mask

  const Dataset& ds_;
  std::unique_ptr<FrameSource> video_;     // raw video frames, sequential
  std::unique_ptr<FrameSource> prepared_;  // the dataset's own frames, for other formats
};
// `own`: CV_8U of the map's size (pb::DepthMap.own), or empty.
pb::DepthMap DepthMapToProto(const DepthMap& map, int view, pb::MapKind kind, const cv::Mat& own = cv::Mat());
// Throws InputError naming `what` and the field. `own` (may be null): the own-depth mask, empty when the
// message has none (its size is checked either way).
DepthMap DepthMapFromProto(const pb::DepthMap& map, int width, int height, const std::string& what,
                           cv::Mat* own = nullptr);

// A job's options are `lfrecon run`'s flags (pipeline/pipeline_flags.h); the
// pipeline options follow from them by the same mapping as run's (OptionsFromFlags).
// Every job option is validated here (PipelineOptions::Check, throws OptionError):
// ingest refuses a job whose options would fail later.
ReconstructionFlags JobFlags(const pb::JobOptions& options);
PipelineOptions JobPipelineOptions(const pb::JobOptions& options);
// The job's fusion grid options for V, as the embedded pipeline sets them up; throws OptionError.
FusionOptions JobFusionOptions(const PipelineOptions& options, const BoundingBox& volume);

// The manifest of job `id` for `spec` opened as `dataset` (what ingest writes).
pb::JobManifest MakeManifest(const std::string& id, const pb::JobSpec& spec, const Dataset& dataset);
// The DatasetOptions a JobSpec names; throws OptionError.
DatasetOptions ToDatasetOptions(const pb::JobSpec& spec);
// The spec's V (JobSpec.bbox), or nothing when it gives none; throws
// OptionError unless it is 6 numbers with each max above its min.
std::optional<BoundingBox> SpecVolume(const pb::JobSpec& spec);

// A job as a worker or the aggregator sees it: the manifest decoded.
struct JobGeometry {
  std::string id;
  std::vector<PinholeView> views;
  std::vector<std::string> names;
  BoundingBox volume;
  PipelineOptions options;
  // The job's plan (views selected, neighbours, on_grid, voters, colour and
  // carving frames, fusion options), as `lfrecon run` computes it for the same
  // cameras and options.
  ReconstructionPlan plan;
  // A client-pushed stream still open (no manifest yet, V given): `views` are
  // its frames 0..n-1 stored so far (the first gap ends them), `plan` is the
  // plan of that prefix, final for its settled frames (ReconstructionPlan::
  // SettledFrames) and, for selection and on_grid, for every frame of it.
  bool open = false;
  // Whether a frame of the job may carry an object mask (Frame.mask): false
  // when none does (JobManifest.frame_masks false; of an open stream, none of
  // its stored frames), so no frame file need be read for its mask. True when
  // the manifest does not say (a store written before the field).
  bool frame_masks = true;
};
// The manifest's geometry; for an open stream that gives V (GrowingStream), its
// received prefix (LoadStreamGeometry). Throws InputError / OptionError.
JobGeometry LoadJobGeometry(const JobStore& store, const std::string& id);
// The StreamOpen (stream.pb) of `id` when it is a stream whose plan can grow
// before its end: still open (no manifest yet) and V given in its spec. Without V
// (estimated from every camera) the plan waits for the end: nothing.
std::optional<pb::StreamOpen> GrowingStream(const JobStore& store, const std::string& id);
// The geometry of an open stream (GrowingStream): views = its stored frames 0..n-1
// (n may be 0: no plan yet, only its fusion options). Throws InputError / OptionError.
JobGeometry LoadStreamGeometry(const JobStore& store, const std::string& id);
// Appends the frames stored since (n, n+1, ... while stored) to an open stream's
// geometry and recomputes its plan; true when any was added. `lazy`: not while
// no frame settles (ReconstructionPlan::SettledDepthFrames is 0, so nothing of
// the plan is used yet: a long gap on a shorter stream), which spares a plan per
// frame; the plan is then the last one computed, of fewer frames.
bool GrowStreamGeometry(const JobStore& store, JobGeometry* geo, bool lazy = false);

}  // namespace lfrecon::svc
