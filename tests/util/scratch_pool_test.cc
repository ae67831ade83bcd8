#include "util/scratch_pool.h"

#include <gtest/gtest.h>

#include <cstring>

namespace lfrecon {

TEST(ScratchPool, ReusesAReturnedBlockThatIsLargeEnough) {
  ScratchPool pool(2);
  void* first = nullptr;
  {
    ScratchPool::Lease a = pool.Acquire(1000);
    first = a.data();
    std::memset(a.data(), 1, 1000);
  }
  EXPECT_EQ(pool.FreeBytes(), 1000u);
  ScratchPool::Lease b = pool.Acquire(800);  // fits in the returned block
  EXPECT_EQ(b.data(), first);
  EXPECT_EQ(pool.FreeBytes(), 0u);
  ScratchPool::Lease c = pool.Acquire(2000);  // none free: a new one
  EXPECT_NE(c.data(), first);
}

TEST(ScratchPool, KeepsOnlyTheLargestFreeBlocks) {
  ScratchPool pool(2);
  {
    ScratchPool::Lease a = pool.Acquire(100), b = pool.Acquire(300), c = pool.Acquire(200);
  }
  EXPECT_EQ(pool.FreeBytes(), 500u);  // 300 + 200 kept, 100 freed
  ScratchPool::Lease big = pool.Acquire(250);
  EXPECT_EQ(pool.FreeBytes(), 200u);  // took the 300-byte block, the smallest that fits
}

TEST(ScratchPool, AMovedLeaseReturnsItsBlockOnce) {
  ScratchPool pool(4);
  {
    ScratchPool::Lease a = pool.Acquire(64);
    ScratchPool::Lease b = std::move(a);
    ScratchPool::Lease c;
    c = std::move(b);
    EXPECT_NE(c.data(), nullptr);
  }
  EXPECT_EQ(pool.FreeBytes(), 64u);
}

}  // namespace lfrecon
