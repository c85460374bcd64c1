#pragma once
// Progress reporting and cancellation, passed into every long-running engine call.

#include <functional>
#include <string>

#include "engine/util/check.h"

namespace omnirig {

// A sink for progress and a source of cancellation. Both callbacks are optional. Engine code
// calls Report() at natural steps (per image, per frame, per solver iteration) and
// ThrowIfCancelled() at least every few hundred milliseconds of work.
struct ProgressSink {
  // fraction in [0, 1] of the whole call; stage is a short machine-friendly word
  // ("detect", "solve", ...); message is for humans.
  std::function<void(double fraction, const std::string& stage, const std::string& message)>
      report;
  std::function<bool()> is_cancelled;

  void Report(double fraction, const std::string& stage, const std::string& message = "") const {
    if (report) report(fraction, stage, message);
  }
  bool IsCancelled() const { return is_cancelled && is_cancelled(); }
  void ThrowIfCancelled() const {
    if (IsCancelled()) throw Cancelled();
  }
};

}  // namespace omnirig
