#include "util/memory.h"

#include <malloc.h>

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

void UseMmapForLargeBlocks() {
#ifdef M_MMAP_THRESHOLD
  // A fixed threshold also turns off glibc's dynamic raising of it.
  mallopt(M_MMAP_THRESHOLD, 1 << 20);
#endif
}

}  // namespace lfrecon
