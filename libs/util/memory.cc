#include "util/memory.h"

#include <malloc.h>

#include <cstdlib>
#include <fstream>
#include <string>

namespace lfrecon {
namespace {
std::int64_t ReadStatusKb(const std::string& key) {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(key, 0) == 0) return std::stoll(line.substr(key.size())) * 1024;
  }
  return 0;
}
}  // namespace

std::int64_t PeakRssBytes() { return ReadStatusKb("VmHWM:"); }
std::int64_t CurrentRssBytes() { return ReadStatusKb("VmRSS:"); }

void ConfigureHeap() {
#if defined(__GLIBC__)  // mallopt and these parameters are glibc's; other C libraries keep their defaults
  if (!std::getenv("MALLOC_MMAP_THRESHOLD_")) mallopt(M_MMAP_THRESHOLD, static_cast<int>(kMmapThresholdBytes));
  if (!std::getenv("MALLOC_TRIM_THRESHOLD_")) mallopt(M_TRIM_THRESHOLD, static_cast<int>(kTrimThresholdBytes));
  if (!std::getenv("MALLOC_TOP_PAD_")) mallopt(M_TOP_PAD, static_cast<int>(kTopPadBytes));
#endif
}

}  // namespace lfrecon
