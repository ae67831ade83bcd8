#pragma once
// Large scratch buffers kept from one call to the next. A block above glibc's
// mmap threshold (32 MiB, the most it allows; util/memory.h) is mapped for
// each allocation and unmapped when freed, so each use faults it in page by
// page and the kernel zeroes every page: ~11 k faults for the densification's
// 44 MiB filter channels of one 720p view. A pool keeps such blocks mapped.
#include <cstddef>
#include <memory>
#include <mutex>
#include <vector>

namespace lfrecon {

class ScratchPool {
 public:
  // A buffer of at least `bytes` (contents undefined) until the lease ends.
  class Lease {
   public:
    Lease() = default;
    Lease(Lease&& other) noexcept = default;
    Lease& operator=(Lease&& other) noexcept;
    Lease(const Lease&) = delete;
    Lease& operator=(const Lease&) = delete;
    ~Lease();
    void* data() const { return block_.get(); }

   private:
    friend class ScratchPool;
    Lease(ScratchPool* pool, std::unique_ptr<std::byte[]> block, std::size_t size)
        : pool_(pool), block_(std::move(block)), size_(size) {}
    void Return();
    ScratchPool* pool_ = nullptr;
    std::unique_ptr<std::byte[]> block_;
    std::size_t size_ = 0;
  };

  // max_free: blocks kept while no lease holds them (the largest are kept).
  explicit ScratchPool(int max_free = 2) : max_free_(max_free) {}
  Lease Acquire(std::size_t bytes);
  // Bytes held by free blocks.
  std::size_t FreeBytes() const;

 private:
  struct Block {
    std::unique_ptr<std::byte[]> data;
    std::size_t size;
  };
  void Release(std::unique_ptr<std::byte[]> block, std::size_t size);
  mutable std::mutex mutex_;
  std::vector<Block> free_;
  int max_free_;
};

}  // namespace lfrecon
