#include "util/scratch_pool.h"

#include <algorithm>

namespace lfrecon {

ScratchPool::Lease& ScratchPool::Lease::operator=(Lease&& other) noexcept {
  if (this != &other) {
    Return();
    pool_ = other.pool_;
    block_ = std::move(other.block_);
    size_ = other.size_;
    other.pool_ = nullptr;
  }
  return *this;
}

ScratchPool::Lease::~Lease() { Return(); }

void ScratchPool::Lease::Return() {
  if (pool_ && block_) pool_->Release(std::move(block_), size_);
  pool_ = nullptr;
}

ScratchPool::Lease ScratchPool::Acquire(std::size_t bytes) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    // The smallest free block that is large enough.
    auto best = free_.end();
    for (auto it = free_.begin(); it != free_.end(); ++it)
      if (it->size >= bytes && (best == free_.end() || it->size < best->size)) best = it;
    if (best != free_.end()) {
      Block b = std::move(*best);
      free_.erase(best);
      return Lease(this, std::move(b.data), b.size);
    }
  }
  // new[] of std::byte leaves the memory uninitialised (no page touched yet).
  return Lease(this, std::unique_ptr<std::byte[]>(new std::byte[bytes]), bytes);
}

void ScratchPool::Release(std::unique_ptr<std::byte[]> block, std::size_t size) {
  std::lock_guard<std::mutex> lock(mutex_);
  free_.push_back({std::move(block), size});
  // Keep the largest max_free_ blocks.
  std::sort(free_.begin(), free_.end(), [](const Block& a, const Block& b) { return a.size > b.size; });
  if (static_cast<int>(free_.size()) > max_free_) free_.resize(static_cast<std::size_t>(std::max(0, max_free_)));
}

std::size_t ScratchPool::FreeBytes() const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::size_t total = 0;
  for (const Block& b : free_) total += b.size;
  return total;
}

}  // namespace lfrecon
