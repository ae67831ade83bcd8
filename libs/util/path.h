#pragma once
// Small helpers on file paths shared by the readers and writers.
#include <algorithm>
#include <cctype>
#include <filesystem>
#include <string>

namespace lfrecon {

// The extension with its dot, in ASCII lower case ("IMG.JPG" -> ".jpg"): file
// types are told by extension whatever its case.
inline std::string LowerExtension(const std::filesystem::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext;
}

}  // namespace lfrecon
