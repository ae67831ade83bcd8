#pragma once
#include <cstdint>

namespace lfrecon {

// Peak resident set size of this process in bytes (VmHWM), 0 if unknown.
std::int64_t PeakRssBytes();
// Current resident set size in bytes (VmRSS), 0 if unknown.
std::int64_t CurrentRssBytes();

}  // namespace lfrecon
