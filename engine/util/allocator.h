#pragma once

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
//   (rewriting the same memory at 20 GB/s), three alternating runs of 2026-12-07: the stereo
//   job 0.26-0.29 s a pair against 0.36-0.44 with two arenas alone and 0.37-0.45 with glibc's
//   defaults; SLAM's 40 frames 3.15-3.55 s against 3.44-4.05 and 3.10-3.69; the SLAM dense
//   map's fusion 36-38 % of SLAM's wall time against 37-41 % and 53-56 % (docs/dense.md).
void ConfigureAllocator();

}  // namespace omnirig
