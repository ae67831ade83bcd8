#pragma once
#include <cstdint>

namespace lfrecon {

// Peak resident set size of this process in bytes (VmHWM), 0 if unknown.
std::int64_t PeakRssBytes();
// Current resident set size in bytes (VmRSS), 0 if unknown.
std::int64_t CurrentRssBytes();

// For the mains: heap blocks of at least 1 MiB (a 640×360 float frame is
// 2.6 MiB, 1280×720 10.5 MiB) are mapped and unmapped on their own instead of
// coming from the heap. glibc otherwise raises its mmap threshold to the size
// of the first such block freed (up to 32 MiB), after which frame-sized
// buffers of many threads fragment the heap and stay resident: a 40-frame
// 1280×720 pipeline run held 1006 MiB after its depth stage, 692-769 MiB with
// this (scale_bench, docs/benchmarks.md).
void UseMmapForLargeBlocks();

}  // namespace lfrecon
