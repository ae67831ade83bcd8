#include "io/colmap_dense.h"

#include <cstdint>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "util/error.h"

namespace lfrecon {
namespace fs = std::filesystem;

void WriteColmapDenseMap(const fs::path& path, const cv::Mat& map) {
  if (map.empty() || map.depth() != CV_32F || map.channels() > 4)
    throw InputError(path.string(), "a COLMAP dense map is float32 with 1 to 4 channels");
  std::vector<cv::Mat> planes;
  cv::split(map, planes);
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw InputError(path.string(), "cannot open file for writing");
  out << map.cols << "&" << map.rows << "&" << map.channels() << "&";
  // x86 and ARM Linux are little-endian, the file's byte order.
  for (const cv::Mat& plane : planes)
    for (int r = 0; r < plane.rows; ++r)
      out.write(reinterpret_cast<const char*>(plane.ptr<float>(r)),
                static_cast<std::streamsize>(plane.cols * sizeof(float)));
  out.close();
  if (!out) throw InputError(path.string(), "write failed");
}

cv::Mat ReadColmapDenseMap(const fs::path& path) {
  const std::string file = path.string();
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(file, "cannot open file");
  long long dims[3] = {0, 0, 0};
  for (long long& d : dims) {
    std::string digits;
    char c = 0;
    while (in.get(c) && c != '&') {
      if (c < '0' || c > '9' || digits.size() > 9) throw InputError(file, "header", "expected WIDTH&HEIGHT&CHANNELS&");
      digits += c;
    }
    if (c != '&' || digits.empty()) throw InputError(file, "header", "expected WIDTH&HEIGHT&CHANNELS&");
    d = std::stoll(digits);
  }
  const long long w = dims[0], h = dims[1], ch = dims[2];
  if (w <= 0 || h <= 0 || ch <= 0 || ch > 4 || w * h * ch > (1ll << 26))
    throw InputError(file, "header", "size " + std::to_string(w) + "x" + std::to_string(h) + "x" + std::to_string(ch) +
                                         " out of range (1-4 channels, at most 2^26 values)");
  std::vector<cv::Mat> planes;
  for (long long k = 0; k < ch; ++k) {
    cv::Mat plane(static_cast<int>(h), static_cast<int>(w), CV_32F);
    in.read(reinterpret_cast<char*>(plane.data), static_cast<std::streamsize>(w * h * sizeof(float)));
    if (in.gcount() != static_cast<std::streamsize>(w * h * sizeof(float)))
      throw InputError(file, "data ends before " + std::to_string(w * h * ch) + " values");
    planes.push_back(plane);
  }
  cv::Mat out;
  cv::merge(planes, out);
  return out;
}

}  // namespace lfrecon
