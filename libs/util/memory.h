#pragma once
#include <cstdint>

namespace lfrecon {

// Peak resident set size of this process in bytes (VmHWM), 0 if unknown.
std::int64_t PeakRssBytes();
// Current resident set size in bytes (VmRSS), 0 if unknown.
std::int64_t CurrentRssBytes();

// For the mains: glibc heap settings for a process whose threads allocate and
// free frame-sized buffers all the time (a 640×360 float frame is 2.6 MiB,
// 1280×720 10.5 MiB; a neighbour is expanded and pre-smoothed for each view it
// serves, its photoconsistency makes patch means and grey levels, ...).
// - Blocks below kMmapThresholdBytes come from the heap and are reused there;
//   the threshold is fixed (glibc's dynamic one starts at 128 KiB). Before, it
//   was fixed at 1 MiB so that frame-sized blocks were mapped and unmapped on
//   their own, to keep the heap from fragmenting; but then every such block is
//   faulted in page by page and zeroed by the kernel each time: a 200-frame
//   1280×720 pipeline run (scale_bench) took 363 s with 14.3 M minor faults
//   and 113 s of system time, 157 s and 0.9 M with this, for a peak RSS of
//   1459 MiB instead of 1387 (docs/benchmarks.md, "Heap settings").
// - Free memory at the top of a heap is given back to the system only above
//   kTrimThresholdBytes, and a heap grows by kTopPadBytes at a time: a fixed
//   mmap threshold also fixes glibc's trim threshold at 128 KiB, and then every
//   burst of smaller blocks was given back and faulted in again.
// A MALLOC_*_ environment variable the user set (mallopt(3)) is left as set.
void ConfigureHeap();
inline constexpr long kMmapThresholdBytes = 32L << 20;
inline constexpr long kTrimThresholdBytes = 64L << 20;
inline constexpr long kTopPadBytes = 8L << 20;

}  // namespace lfrecon
