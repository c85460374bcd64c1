// server::ParseContentRange on any header value (a resumable upload's chunk): HttpError 400 or
// a range with 0 <= first <= last < total that prints back to a header parsing to itself.

#include <cstddef>
#include <cstdint>
#include <string>

#include "fuzz/fuzz_check.h"
#include "server/content_range.h"
#include "server/http.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using omnirig::server::ContentRange;
  const std::string text(reinterpret_cast<const char*>(data), size);
  ContentRange range;
  try {
    range = omnirig::server::ParseContentRange(text);
  } catch (const omnirig::server::HttpError& e) {
    FUZZ_CHECK(e.status == 400);
    return 0;
  }
  FUZZ_CHECK(0 <= range.first && range.first <= range.last && range.last < range.total);
  FUZZ_CHECK(range.length() >= 1);
  const ContentRange again = omnirig::server::ParseContentRange(
      "bytes " + std::to_string(range.first) + "-" + std::to_string(range.last) + "/" +
      std::to_string(range.total));
  FUZZ_CHECK(again.first == range.first && again.last == range.last &&
             again.total == range.total);
  return 0;
}
