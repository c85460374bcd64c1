#pragma once
// Names that become paths under the data folder: image names (one folder level allowed, e.g.
// "cam0/000012.png") and artifact names. A name is accepted only when it is already safe, never
// rewritten: a silent rewrite would let two different names map to one file and break the
// idempotent upload contract. Refused: empty or over-long names, absolute paths, "." and ".."
// components, hidden components (leading '.'), backslashes, and any character outside
// [A-Za-z0-9._+-].

#include <string>

namespace omnirig::storage {

constexpr size_t kMaxNameLength = 200;
constexpr size_t kMaxNameComponentLength = 100;

// Returns the name unchanged when safe; throws std::invalid_argument saying why otherwise.
// `max_levels` is the number of path components allowed (2 = one folder level).
std::string CheckSafeName(const std::string& name, int max_levels = 2);

}  // namespace omnirig::storage
