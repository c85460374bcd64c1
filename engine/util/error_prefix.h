#pragma once
// Errors that name the item they concern.

#include <string>

#include "engine/util/check.h"

namespace omnirig {

// Returns f(); an InvalidArgument it throws gets `prefix` before its message, so that a check
// deep in a call names the request's field or item ("field 'board': ", "pair 'a.png': ").
template <typename F>
auto WithErrorPrefix(const std::string& prefix, F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const InvalidArgument& e) {
    throw InvalidArgument(prefix + e.what(), e.where());
  }
}

}  // namespace omnirig
