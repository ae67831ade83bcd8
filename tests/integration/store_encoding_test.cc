// The compact job store (common/job_store.h): frames kept as encoded on disk
// (PNG, JPEG) or as 8-bit lossless PNG, decoded (and downscaled / undistorted)
// on read to exactly the pixels io/Dataset hands `lfrecon run`, at a fraction
// of the 12 bytes a pixel of the float frames; image headers checked against
// the camera before anything is decoded.
#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/videoio.hpp>
#include <algorithm>

#include "common/job_store.h"
#include "common/test_util.h"
#include "integration/daemon_process.h"
#include "io/dataset.h"
#include "util/error.h"

namespace lfrecon::svc {
namespace {
namespace fs = std::filesystem;

const std::string kBin = std::string(LFRECON_BINARY_DIR) + "/bin/";

void Synth(const fs::path& out, const std::string& format) {
  const auto r = lfrecon::testing::RunShell(kBin + "lfrecon -q synth --scene sphere --frames 6 --width 96 --height 54 "
                                            "--depth-every 0 --no-meshes --format " + format + " --out " + out.string());
  ASSERT_EQ(r.code, 0) << r.output;
}

// Every frame through the store equals the dataset's frame bit for bit, and
// takes the image file's bytes (plus the camera); returns the bytes a pixel stored.
double RoundTrip(const fs::path& data, int max_image_size, const std::string& want_encoding,
                 const fs::path& video = {}) {
  DatasetOptions d;
  if (video.empty()) {
    d.dataset_dir = data;
  } else {
    d.video_path = video;
    d.colmap_dir = data / "sparse";
  }
  d.max_image_size = max_image_size;
  const Dataset ds = Dataset::Open(d);
  StoreFrameEncoder encoder(ds);
  auto frames = ds.OpenFrames();
  double bytes = 0, pixels = 0;
  for (int k = 0; k < ds.NumViews(); ++k) {
    const pb::Frame f = encoder.Encode(k, true);
    EXPECT_EQ(f.encoding(), want_encoding);
    EXPECT_TRUE(f.has_source());
    // Through the store's serialisation, as a worker reads it.
    pb::Frame back;
    EXPECT_TRUE(back.ParseFromString(f.SerializeAsString()));
    const PinholeView v = ds.View(k);
    const cv::Mat got = FrameFromProto(back, v.width, v.height, "frame");
    const cv::Mat want = frames->Read(k).image;
    EXPECT_EQ(got.type(), CV_32FC3);
    EXPECT_EQ(got.size(), want.size());
    EXPECT_EQ(cv::norm(got, want, cv::NORM_INF), 0.0) << "frame " << k;
    const std::size_t stored = f.SerializeAsString().size();
    if (video.empty()) {
      const std::size_t file = fs::file_size(ds.ImagePath(k));
      EXPECT_GE(stored, file);
      EXPECT_LE(stored, file + 400);  // the camera, the source camera, the encoding
    }
    bytes += static_cast<double>(stored);
    pixels += static_cast<double>(v.width) * v.height;
  }
  return bytes / pixels;
}

TEST(StoreEncoding, PngAndJpegFramesAsOnDiskRoundTripExactly) {
  lfrecon::testing::TempDir tmp;
  Synth(tmp.path() / "png", "png");
  Synth(tmp.path() / "jpg", "jpg");
  if (::testing::Test::HasFatalFailure()) return;
  const double png = RoundTrip(tmp.path() / "png", 0, "png");
  const double jpg = RoundTrip(tmp.path() / "jpg", 0, "jpeg");
  // Downscaled on read (--max-image-size): the stored bytes are the file's, the pixels the dataset's.
  const double png_small = RoundTrip(tmp.path() / "png", 64, "png");
  std::printf("store bytes a pixel: png %.3f, jpeg %.3f, png read at 64 px %.3f (float frames: 12)\n", png, jpg,
              png_small);
  // 12 bytes a pixel before; a JPEG capture stays under 1.5, a (noisy, generated) PNG is what its file is.
  EXPECT_LE(jpg, 1.5);
  EXPECT_LE(png, 3.2);
  EXPECT_GT(png_small, png);  // the file's bytes over fewer pixels read
}

// A video's frames: decoded once by ingest (or the client), kept as 8-bit lossless PNG.
TEST(StoreEncoding, VideoFramesAsLosslessPngRoundTripExactly) {
  lfrecon::testing::TempDir tmp;
  Synth(tmp.path() / "png", "png");
  if (::testing::Test::HasFatalFailure()) return;
  const fs::path video = tmp.path() / "clip.avi";
  {
    cv::VideoWriter writer(video.string(), cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0, cv::Size(96, 54));
    if (!writer.isOpened()) GTEST_SKIP() << "OpenCV cannot write MJPG video here";
    std::vector<fs::path> images;
    for (const auto& e : fs::directory_iterator(tmp.path() / "png" / "images")) images.push_back(e.path());
    std::sort(images.begin(), images.end());
    for (const fs::path& p : images) writer.write(cv::imread(p.string()));
  }
  const double bpp = RoundTrip(tmp.path() / "png", 0, "png", video);
  const double small = RoundTrip(tmp.path() / "png", 64, "png", video);
  std::printf("store bytes a pixel: MJPG video frames as PNG %.3f (read at 64 px: %.3f)\n", bpp, small);
  EXPECT_LE(bpp, 3.2);
}

TEST(StoreEncoding, RawFramesAreLosslessPngOrFloat) {
  cv::Mat u8(27, 48, CV_8UC3);
  cv::randu(u8, 0, 256);
  cv::Mat smooth;
  cv::GaussianBlur(u8, smooth, cv::Size(0, 0), 3);  // a camera-like image: PNG compresses it
  const cv::Mat f = ToFloatBgr(smooth);
  pb::Camera cam;
  cam.set_width(48);
  cam.set_height(27);
  const pb::Frame png = FrameToProto(3, f, cam);
  EXPECT_EQ(png.encoding(), "png");
  EXPECT_LT(png.data().size(), 48u * 27 * 3);
  EXPECT_EQ(cv::norm(FrameFromProto(png, 48, 27, "png"), f, cv::NORM_INF), 0.0);
  // Raw 8-bit from a client: stored as PNG, the same pixels.
  pb::Frame raw;
  raw.set_index(3);
  *raw.mutable_camera() = cam;
  raw.set_encoding("bgr8");
  raw.set_data(std::string(reinterpret_cast<const char*>(smooth.data), smooth.total() * 3));
  const pb::Frame stored = CompactFrameProto(raw, "raw");
  EXPECT_EQ(stored.encoding(), "png");
  EXPECT_EQ(cv::norm(FrameFromProto(stored, 48, 27, "raw"), f, cv::NORM_INF), 0.0);
  raw.set_data("short");
  EXPECT_THROW(CompactFrameProto(raw, "raw"), InputError);
  // Not 8-bit: kept as floats, still lossless; the old encoding still reads.
  cv::Mat g = f.clone();
  g.at<cv::Vec3f>(0, 0)[0] = 0.123456f;
  const pb::Frame fl = FrameToProto(3, g, cam);
  EXPECT_EQ(fl.encoding(), "f32-bgr");
  EXPECT_EQ(cv::norm(FrameFromProto(fl, 48, 27, "f32"), g, cv::NORM_INF), 0.0);
  EXPECT_THROW(FrameFromProto(fl, 47, 27, "f32"), InputError);
}

TEST(StoreEncoding, HeaderCheckedAgainstTheCameraBeforeDecoding) {
  // A PNG whose header claims 60000 x 60000 (a decode bomb) for a 48 x 27 camera: refused from its header.
  cv::Mat small(27, 48, CV_8UC3, cv::Scalar(10, 20, 30));
  std::vector<uchar> buf;
  ASSERT_TRUE(cv::imencode(".png", small, buf));
  std::string bytes(buf.begin(), buf.end());
  auto be32 = [&](std::size_t at, std::uint32_t v) {
    for (int i = 0; i < 4; ++i) bytes[at + i] = static_cast<char>((v >> (24 - 8 * i)) & 0xff);
  };
  be32(16, 60000);
  be32(20, 60000);
  pb::Frame f;
  f.set_encoding("png");
  f.set_data(bytes);
  try {
    FrameFromProto(f, 48, 27, "bomb");
    ADD_FAILURE() << "decoded";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("image header is 60000x60000 but its camera is 48x27"), std::string::npos)
        << e.what();
  }
  // With a source camera the stored size is what the header must match.
  *f.mutable_source() = SourceCameraToProto(Camera::Pinhole(48, 27, 40, 40, 24, 13.5), 48, 27);
  EXPECT_THROW(FrameFromProto(f, 48, 27, "bomb"), InputError);
  f.mutable_source()->set_model("NOT_A_MODEL");
  EXPECT_THROW(FrameFromProto(f, 48, 27, "bad model"), InputError);
  // A truncated JPEG is refused rather than decoded half grey.
  ASSERT_TRUE(cv::imencode(".jpg", small, buf));
  pb::Frame j;
  j.set_encoding("jpeg");
  j.set_data(std::string(buf.begin(), buf.begin() + static_cast<long>(buf.size() / 2)));
  EXPECT_THROW(FrameFromProto(j, 48, 27, "cut"), InputError);
}

// Object masks travel with their frames (Frame.mask): each frame of a masked
// dataset carries its mask as `lfrecon run` reads it (Dataset::ReadMask:
// downscaled with the frame, 0/255), as lossless PNG, a few bytes a pixel
// at most; a frame without a mask carries none; a mask's PNG header is checked
// against the frame's size before it is decoded.
TEST(StoreEncoding, MasksTravelWithTheirFramesExactly) {
  lfrecon::testing::TempDir tmp;
  const fs::path data = tmp.path() / "masked";
  const auto r = lfrecon::testing::RunShell(kBin + "lfrecon -q synth --scene sphere --masks --frames 6 --width 96 "
                                            "--height 54 --depth-every 0 --no-meshes --format jpg --out " +
                                            data.string());
  ASSERT_EQ(r.code, 0) << r.output;
  for (int max_image_size : {0, 64}) {
    DatasetOptions d;
    d.dataset_dir = data;
    d.max_image_size = max_image_size;
    const Dataset ds = Dataset::Open(d);
    ASSERT_TRUE(ds.HasMasks());
    StoreFrameEncoder encoder(ds);
    double mask_bytes = 0, pixels = 0;
    for (int k = 0; k < ds.NumViews(); ++k) {
      pb::Frame back;
      ASSERT_TRUE(back.ParseFromString(encoder.Encode(k, true).SerializeAsString()));
      const PinholeView v = ds.View(k);
      const cv::Mat got = MaskFromProto(back, v.width, v.height, "frame " + std::to_string(k));
      const cv::Mat want = ds.ReadMask(k);
      ASSERT_EQ(got.type(), CV_8UC1);
      ASSERT_EQ(got.size(), want.size());
      EXPECT_EQ(cv::norm(got, want, cv::NORM_INF), 0.0) << "mask of frame " << k;
      EXPECT_GT(cv::countNonZero(got), 0);
      EXPECT_LT(cv::countNonZero(got), v.width * v.height);
      mask_bytes += static_cast<double>(back.mask().size());
      pixels += static_cast<double>(v.width) * v.height;
    }
    std::printf("masks read at %s: %.3f bytes a pixel stored\n",
                max_image_size ? std::to_string(max_image_size).c_str() : "full size", mask_bytes / pixels);
    EXPECT_LT(mask_bytes / pixels, 0.5);
  }
  // No mask: an empty Mat. A header claiming 60000 x 60000 for a 96 x 54 frame: refused undecoded, naming the frame.
  pb::Frame f;
  EXPECT_TRUE(MaskFromProto(f, 96, 54, "frame 3").empty());
  std::vector<uchar> buf;
  ASSERT_TRUE(cv::imencode(".png", cv::Mat(54, 96, CV_8U, cv::Scalar(255)), buf));
  std::string bytes(buf.begin(), buf.end());
  for (int at : {16, 20})
    for (int i = 0; i < 4; ++i) bytes[at + i] = static_cast<char>((60000u >> (24 - 8 * i)) & 0xff);
  f.set_mask(bytes);
  try {
    MaskFromProto(f, 96, 54, "frame 3");
    ADD_FAILURE() << "decoded";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("frame 3 [mask]: mask is 60000x60000, its frame 96x54"), std::string::npos)
        << e.what();
  }
}

}  // namespace
}  // namespace lfrecon::svc
