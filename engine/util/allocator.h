#pragma once

#include <cstddef>
#include <new>

namespace omnirig {

// Sets the process's heap (glibc malloc) the way omnirig's processes run best; call it first in
// main, before any thread starts. Does nothing with another C library.
//
// - Two arenas. glibc gives threads that allocate at once arenas of their own, up to 8 per core,
//   and an arena keeps the most its threads ever held. The service's HTTP threads decode uploads
//   and live frames while jobs run SIFT and adjustments on theirs: in a soak with live robots
//   (docs/soak.md) 16 arenas held about 320 MB with 15-45 MB in use, and the resident memory kept
//   growing; with two arenas it was half and flat.
// - Freed memory kept for reuse: blocks up to 32 MB come from the arenas (not mmap), an arena
//   gives memory back to the system only when more than 256 MB lies free at its top, and it
//   grows 64 MB at a time. A page the process touches for the first time costs a fault, and the
//   dense stereo allocates tens of MB of buffers a pair (its grid's matrices, SGBM's cost rows):
//   with glibc's defaults those went back to the system after each pair and were faulted in
//   again for the next. On a 2-core virtual machine where a first touch ran at 0.36 GB/s
//   (rewriting the same memory at 20 GB/s), 2026-12-07, alternating runs: the stereo job
//   0.26-0.29 s a pair against 0.36-0.44 with two arenas alone and 0.37-0.45 with glibc's
//   defaults; the SLAM dense map's fusion 36-38 % of SLAM's wall time against 53-56 % with the
//   defaults; bench_slam's whole process 4.6 % less wall time than with the defaults, its peak
//   memory 546 MiB against 485 (docs/dense.md).
void ConfigureAllocator();

// Memory for large arrays that a process fills soon after it allocates them (a dense map's voxel
// table): blocks of at least kLargeBlockBytes are mapped on their own and advised for
// transparent huge pages (Linux: one fault fills 2 MB instead of 4 kB), smaller ones come from
// the heap. The fused map's voxel table grows to hundreds of MB; on the virtual machine above,
// 4 kB faults made its first touch cost more than the fusion's arithmetic (the stereo job's
// merged cloud, 2026-12-07: 1.06-1.13 s a pair with the heap, 0.42-0.51 with huge pages).
// Throws std::bad_alloc when the system has no memory left.
inline constexpr std::size_t kLargeBlockBytes = std::size_t{4} << 20;
void* AllocateLarge(std::size_t bytes);
void FreeLarge(void* block, std::size_t bytes) noexcept;

// A std::allocator for std::vector of such arrays (AllocateLarge).
template <typename T>
struct LargeArrayAllocator {
  using value_type = T;
  LargeArrayAllocator() = default;
  template <typename U>
  LargeArrayAllocator(const LargeArrayAllocator<U>&) noexcept {}  // NOLINT: rebinding
  T* allocate(std::size_t n) {
    if (n > static_cast<std::size_t>(-1) / sizeof(T)) throw std::bad_alloc();
    return static_cast<T*>(AllocateLarge(n * sizeof(T)));
  }
  void deallocate(T* p, std::size_t n) noexcept { FreeLarge(p, n * sizeof(T)); }
  template <typename U>
  bool operator==(const LargeArrayAllocator<U>&) const noexcept {
    return true;
  }
  template <typename U>
  bool operator!=(const LargeArrayAllocator<U>&) const noexcept {
    return false;
  }
};

}  // namespace omnirig
