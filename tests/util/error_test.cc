#include "util/error.h"

#include <gtest/gtest.h>

#include "util/memory.h"
#include "util/progress.h"

namespace lfrecon {
namespace {

TEST(InputError, NamesFileAndField) {
  const InputError e("sparse/images.txt", "line 7: QW", "not a number");
  EXPECT_STREQ(e.what(), "sparse/images.txt [line 7: QW]: not a number");
  EXPECT_EQ(e.file(), "sparse/images.txt");
  EXPECT_EQ(e.field(), "line 7: QW");
  EXPECT_STREQ(InputError("a.png", "cannot be read").what(), "a.png: cannot be read");
}

TEST(Memory, PeakRssIsAtLeastCurrent) {
  EXPECT_GT(CurrentRssBytes(), 0);
  EXPECT_GE(PeakRssBytes(), CurrentRssBytes());
}

TEST(Progress, CountsAdvances) {
  Progress p("test", 10, 1000.0);
  for (int i = 0; i < 10; ++i) p.Advance();
  EXPECT_EQ(p.done(), 10);
}

}  // namespace
}  // namespace lfrecon
