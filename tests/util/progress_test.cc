#include "util/progress.h"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

namespace lfrecon {
namespace {

// A busy loop counts as CPU time, a sleep does not: the Timer's CPU seconds
// are the process's, not the wall clock's.
TEST(Timer, CpuSecondsCountWorkNotSleep) {
  Timer busy;
  volatile double x = 0;
  while (busy.Seconds() < 0.2) x = x + 1.0;
  EXPECT_GT(busy.CpuSeconds(), 0.05);

  Timer idle;
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  EXPECT_GE(idle.Seconds(), 0.19);
  EXPECT_LT(idle.CpuSeconds(), 0.1);
}

}  // namespace
}  // namespace lfrecon
