#pragma once
// Contract checks that throw instead of aborting: nothing reachable from a request may take the
// process down. Expected outcomes (an image with no board, RANSAC without a model) are values,
// not exceptions; these macros are for violated preconditions and invalid options.

#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

namespace omnirig {

// Thrown when a caller breaks a documented precondition or gives invalid options. The API layer
// turns it into HTTP 400 with the message; where() ("calib/pipeline.cc:120" for a failed
// OMNIRIG_CHECK, else empty) is for logs only, never for API users.
class InvalidArgument : public std::invalid_argument {
 public:
  explicit InvalidArgument(const std::string& message, std::string where = "")
      : std::invalid_argument(message), where_(std::move(where)) {}
  const std::string& where() const { return where_; }

 private:
  std::string where_;
};

// Thrown when an engine run is cancelled through its ProgressSink.
class Cancelled : public std::runtime_error {
 public:
  Cancelled() : std::runtime_error("cancelled") {}
};

namespace internal {
// The last two components of a source path ("calib/pipeline.cc"): enough to find the check, and
// free of the build machine's directories, which would otherwise reach API users in job errors.
inline const char* ShortSourcePath(const char* file) {
  const char* last = nullptr;
  const char* before_last = nullptr;
  for (const char* c = file; *c != '\0'; ++c) {
    if (*c == '/' || *c == '\\') {
      before_last = last;
      last = c;
    }
  }
  return before_last != nullptr ? before_last + 1 : file;
}

[[noreturn]] inline void ThrowCheck(const char* file, int line, const std::string& what) {
  throw InvalidArgument(what, std::string(ShortSourcePath(file)) + ":" + std::to_string(line));
}
}  // namespace internal

}  // namespace omnirig

#define OMNIRIG_CHECK(cond, msg)                                                    \
  do {                                                                             \
    if (!(cond)) {                                                                 \
      std::ostringstream omnirig_check_os_;                                        \
      omnirig_check_os_ << msg;                                                    \
      ::omnirig::internal::ThrowCheck(__FILE__, __LINE__, omnirig_check_os_.str()); \
    }                                                                              \
  } while (false)
