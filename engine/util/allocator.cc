#include "engine/util/allocator.h"

#if defined(__GLIBC__)
#include <malloc.h>
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

}  // namespace omnirig
