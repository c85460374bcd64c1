// storage::CheckVideoContainer on any bytes (an uploaded video, checked by its container
// structure with seeks): a verdict, never a crash; an accepted file names its container.
// The file is an in-memory file (memfd), reached by its /proc path as an upload's would be.

#include <sys/mman.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <string>

#include "fuzz/fuzz_check.h"
#include "storage/video_container.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using omnirig::storage::VideoContainer;
  static const int fd = memfd_create("omnirig-fuzz-video", 0);
  FUZZ_CHECK(fd >= 0);
  FUZZ_CHECK(ftruncate(fd, 0) == 0);
  size_t written = 0;
  while (written < size) {
    const ssize_t n = pwrite(fd, data + written, size - written, static_cast<off_t>(written));
    FUZZ_CHECK(n > 0);
    written += static_cast<size_t>(n);
  }
  const VideoContainer video =
      omnirig::storage::CheckVideoContainer("/proc/self/fd/" + std::to_string(fd));
  if (video.status == VideoContainer::Status::kOk) {
    FUZZ_CHECK(!video.format.empty() && !video.content_type.empty());
    FUZZ_CHECK(video.problem.empty());
  } else {
    FUZZ_CHECK(!video.problem.empty());
  }
  return 0;
}
