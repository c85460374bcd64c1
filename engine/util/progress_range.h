#pragma once
// Progress of one part of a longer call.

#include <string>

#include "engine/util/progress.h"

namespace omnirig {

// A sink for one part of a call: its fractions in [0, 1] map onto [begin, end] of `progress`,
// sharing its cancellation.
inline ProgressSink SubRange(const ProgressSink& progress, double begin, double end) {
  return {[progress, begin, end](double fraction, const std::string& stage,
                                 const std::string& message) {
            progress.Report(begin + (end - begin) * fraction, stage, message);
          },
          progress.is_cancelled};
}

}  // namespace omnirig
