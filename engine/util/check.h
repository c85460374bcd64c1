#pragma once
// Contract checks that throw instead of aborting: nothing reachable from a request may take the
// process down. Expected outcomes (an image with no board, RANSAC without a model) are values,
// not exceptions; these macros are for violated preconditions and invalid options.

#include <sstream>
#include <stdexcept>
#include <string>

namespace omnirig {

// Thrown when a caller breaks a documented precondition or gives invalid options. The API layer
// turns it into HTTP 400 with the message.
class InvalidArgument : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

// Thrown when an engine run is cancelled through its ProgressSink.
class Cancelled : public std::runtime_error {
 public:
  Cancelled() : std::runtime_error("cancelled") {}
};

namespace internal {
[[noreturn]] inline void ThrowCheck(const char* file, int line, const std::string& what) {
  std::ostringstream os;
  os << what << " (" << file << ":" << line << ")";
  throw InvalidArgument(os.str());
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
