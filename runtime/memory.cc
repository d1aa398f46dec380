#include "runtime/memory.h"

#include <malloc.h>
#include <sys/mman.h>

#include <cstdint>
#include <map>
#include <mutex>
#include <opencv2/core.hpp>
#include <opencv2/core/mat.hpp>
#include <unordered_map>
#include <vector>

namespace vellum {
namespace {

constexpr size_t kHugePage = size_t{2} << 20;
// Freed blocks kept for the next stage's images, at most this much in all; beyond it a freed
// block goes back to the kernel.
constexpr size_t kKeptBytes = size_t{256} << 20;

size_t RoundUp(size_t bytes) { return (bytes + kHugePage - 1) / kHugePage * kHugePage; }

// A block of `bytes` (a multiple of 2 MB) at a 2 MB boundary, advised for huge pages.
uchar* MapHuge(size_t bytes) {
  const size_t span = bytes + kHugePage;
  void* p = mmap(nullptr, span, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  if (p == MAP_FAILED) return nullptr;
  const uintptr_t start = reinterpret_cast<uintptr_t>(p);
  const uintptr_t aligned = (start + kHugePage - 1) & ~(kHugePage - 1);
  if (aligned > start) munmap(p, aligned - start);
  const uintptr_t end = start + span;
  if (end > aligned + bytes) {
    munmap(reinterpret_cast<void*>(aligned + bytes), end - aligned - bytes);
  }
  madvise(reinterpret_cast<void*>(aligned), bytes, MADV_HUGEPAGE);  // Advice: may be refused.
  return reinterpret_cast<uchar*>(aligned);
}

// OpenCV's own allocator (StdMatAllocator), but a Mat of 2 MB or more gets a block of its own,
// 2 MB aligned and advised for huge pages; freed blocks are kept for the Mats that follow (a
// pipeline's stages ask for images of the same few sizes), so their pages fault in and are
// zeroed once.
class HugePageMatAllocator final : public cv::MatAllocator {
 public:
  cv::UMatData* allocate(int dims, const int* sizes, int type, void* data0, size_t* step,
                         cv::AccessFlag, cv::UMatUsageFlags) const override {
    size_t total = CV_ELEM_SIZE(type);
    for (int i = dims - 1; i >= 0; --i) {
      if (step) {
        if (data0 && step[i] != cv::Mat::AUTO_STEP) {
          CV_Assert(total <= step[i]);
          total = step[i];
        } else {
          step[i] = total;
        }
      }
      total *= sizes[i];
    }
    uchar* data = static_cast<uchar*>(data0);
    if (!data)
      data = total >= kHugePage ? Take(RoundUp(total)) : static_cast<uchar*>(cv::fastMalloc(total));
    if (!data) CV_Error(cv::Error::StsNoMem, "out of memory");
    cv::UMatData* u = new cv::UMatData(this);
    u->data = u->origdata = data;
    u->size = total;
    if (data0) u->flags |= cv::UMatData::USER_ALLOCATED;
    return u;
  }

  bool allocate(cv::UMatData* u, cv::AccessFlag, cv::UMatUsageFlags) const override {
    return u != nullptr;
  }

  void deallocate(cv::UMatData* u) const override {
    if (!u) return;
    CV_Assert(u->urefcount == 0 && u->refcount == 0);
    if (!(u->flags & cv::UMatData::USER_ALLOCATED)) {
      if (u->size >= kHugePage) {
        Give(u->origdata);
      } else {
        cv::fastFree(u->origdata);
      }
      u->origdata = nullptr;
    }
    delete u;
  }

 private:
  // A block of `bytes`: the smallest kept one that holds it, its tail beyond `bytes` given
  // back; else a new one, and as many kept blocks (the smallest first) given back as it takes,
  // so that what is kept never adds to the most the process holds: the kept and the used
  // together grow only when the used do.
  uchar* Take(size_t bytes) const {
    std::vector<std::pair<uchar*, size_t>> give_back;
    uchar* block = nullptr;
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      auto it = kept_.lower_bound(bytes);
      if (it != kept_.end()) {
        block = it->second;
        if (it->first > bytes) give_back.emplace_back(block + bytes, it->first - bytes);
        kept_bytes_ -= it->first;
        kept_.erase(it);
      } else {
        size_t freed = 0;
        for (auto k = kept_.begin(); k != kept_.end() && freed < bytes; k = kept_.erase(k)) {
          give_back.emplace_back(k->second, k->first);
          freed += k->first;
          kept_bytes_ -= k->first;
        }
      }
    }
    for (const auto& [start, size] : give_back) munmap(start, size);
    if (!block) block = MapHuge(bytes);
    if (block) {
      const std::lock_guard<std::mutex> lock(mutex_);
      in_use_[block] = bytes;
    }
    return block;
  }

  void Give(uchar* block) const {
    size_t bytes = 0;
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      auto it = in_use_.find(block);
      CV_Assert(it != in_use_.end());
      bytes = it->second;
      in_use_.erase(it);
      if (kept_bytes_ + bytes <= kKeptBytes) {
        kept_.emplace(bytes, block);
        kept_bytes_ += bytes;
        return;
      }
    }
    munmap(block, bytes);
  }

  mutable std::mutex mutex_;
  mutable std::multimap<size_t, uchar*> kept_;         // Freed blocks by size.
  mutable std::unordered_map<uchar*, size_t> in_use_;  // Each block's size.
  mutable size_t kept_bytes_ = 0;
};

}  // namespace

void UseMemoryForOneRun() {
  mallopt(M_MMAP_THRESHOLD, 32 << 20);
  mallopt(M_TRIM_THRESHOLD, 256 << 20);
  static HugePageMatAllocator* allocator = new HugePageMatAllocator;  // Outlives every Mat.
  cv::Mat::setDefaultAllocator(allocator);
}

}  // namespace vellum
