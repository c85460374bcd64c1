#pragma once
// The Content-Range header of a resumable upload's chunk (PUT .../images/{name}).

#include <cstdint>
#include <string>

namespace omnirig::server {

struct ContentRange {
  int64_t first = 0, last = 0, total = 0;
  int64_t length() const { return last - first + 1; }
};

// "bytes FIRST-LAST/TOTAL", with 0 <= FIRST <= LAST < TOTAL; throws HttpError 400 otherwise.
ContentRange ParseContentRange(const std::string& text);

}  // namespace omnirig::server
