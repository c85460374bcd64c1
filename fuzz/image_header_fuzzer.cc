// storage::ProbeImageHeader on any bytes (the first bytes of every uploaded image): it answers
// with a verdict, never crashes; an accepted header names its format and a positive size, a
// refused one says why.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string_view>

#include "fuzz/fuzz_check.h"
#include "storage/image_header.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using omnirig::storage::ImageHeader;
  const std::string_view head(reinterpret_cast<const char*>(data),
                              std::min(size, omnirig::storage::kImageProbeBytes));
  const ImageHeader header = omnirig::storage::ProbeImageHeader(head);
  if (header.status == ImageHeader::Status::kOk) {
    FUZZ_CHECK(header.width > 0 && header.height > 0);
    FUZZ_CHECK(!header.format.empty() && !header.content_type.empty());
    FUZZ_CHECK(header.problem.empty());
  } else {
    FUZZ_CHECK(!header.problem.empty());
  }
  return 0;
}
