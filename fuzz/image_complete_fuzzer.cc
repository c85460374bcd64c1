// An uploaded image's bytes through the check every upload route runs (server/upload_check.h:
// the header, then completeness: PNG chunks and CRCs, JPEG segments, PNM samples, BMP rows).
// The verdict is HttpError 415/422 or the header, never a crash or another exception, and it
// does not depend on how the bytes were split into the chunks that arrived: the bytes are
// checked once whole and once in chunks of 1, 2, 3, ... 31 bytes, and both verdicts must agree.

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>

#include "fuzz/fuzz_check.h"
#include "server/http.h"
#include "server/upload_check.h"

namespace {

// "" and the header when accepted, else the error's status and message.
std::string Verdict(const char* data, size_t size, bool chunked) {
  omnirig::server::ImageCheck check;
  if (!chunked) {
    check.Append(data, size);
  } else {
    size_t chunk = 1;
    for (size_t offset = 0; offset < size; offset += chunk, chunk = chunk % 31 + 1) {
      check.Append(data + offset, std::min(chunk, size - offset));
    }
  }
  try {
    const omnirig::storage::ImageHeader header = check.Finish("upload");
    FUZZ_CHECK(header.status == omnirig::storage::ImageHeader::Status::kOk);
    FUZZ_CHECK(header.width > 0 && header.height > 0);
    return header.format + " " + std::to_string(header.width) + "x" +
           std::to_string(header.height);
  } catch (const omnirig::server::HttpError& e) {
    FUZZ_CHECK(e.status == 415 || e.status == 422);
    return std::to_string(e.status) + " " + e.what();
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const char* bytes = reinterpret_cast<const char*>(data);
  const std::string whole = Verdict(bytes, size, /*chunked=*/false);
  const std::string chunked = Verdict(bytes, size, /*chunked=*/true);
  if (whole != chunked) {
    std::fprintf(stderr, "whole: %s\nchunked: %s\n", whole.c_str(), chunked.c_str());
    FUZZ_CHECK(whole == chunked);
  }
  return 0;
}
