#include "engine/util/allocator.h"

#include <new>

#if defined(__GLIBC__)
#include <malloc.h>
#endif
#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace omnirig {

void ConfigureAllocator() {
#if defined(__GLIBC__)
  mallopt(M_ARENA_MAX, 2);
  mallopt(M_MMAP_THRESHOLD, 32 << 20);
  mallopt(M_TRIM_THRESHOLD, 256 << 20);
  mallopt(M_TOP_PAD, 64 << 20);
#endif
}

void* AllocateLarge(std::size_t bytes) {
#if defined(__linux__)
  if (bytes >= kLargeBlockBytes) {
    void* block = mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (block == MAP_FAILED) throw std::bad_alloc();
    madvise(block, bytes, MADV_HUGEPAGE);  // advice only: a kernel without THP ignores it
    return block;
  }
#endif
  return ::operator new(bytes);
}

void FreeLarge(void* block, std::size_t bytes) noexcept {
  if (block == nullptr) return;
#if defined(__linux__)
  if (bytes >= kLargeBlockBytes) {
    munmap(block, bytes);
    return;
  }
#endif
  ::operator delete(block);
}

}  // namespace omnirig
