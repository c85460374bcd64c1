#include "server/content_range.h"

#include <cstdio>

#include "server/http.h"

namespace omnirig::server {

ContentRange ParseContentRange(const std::string& text) {
  ContentRange range;
  long long first = -1, last = -1, total = -1;
  int consumed = 0;
  if (std::sscanf(text.c_str(), "bytes %lld-%lld/%lld%n", &first, &last, &total, &consumed) != 3 ||
      consumed != static_cast<int>(text.size()) || first < 0 || last < first || total <= last) {
    throw HttpError(400, "invalid_argument",
                    "Content-Range must be 'bytes FIRST-LAST/TOTAL' with 0 <= FIRST <= LAST < "
                    "TOTAL, got '" +
                        text + "'");
  }
  range.first = first;
  range.last = last;
  range.total = total;
  return range;
}

}  // namespace omnirig::server
