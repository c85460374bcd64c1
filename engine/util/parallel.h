#pragma once
// Independent tasks on a few threads, with progress and cancellation from one ProgressSink.

#include <functional>

#include "engine/util/progress.h"

namespace omnirig {

// Runs task(0) .. task(num_tasks - 1) on up to `num_threads` threads (the calling one
// included), in any order; each task writes its results to its own slots, so the outcome does
// not depend on the order or the thread count. `done(i)` runs under a lock after task i
// succeeded: `progress`'s callbacks need not be thread-safe, because every call to them (done's
// and the `cancellation` sink's is_cancelled, which tasks poll) is made under that lock. The
// first exception (Cancelled included) stops further tasks from starting and is rethrown once
// the running ones have returned.
void RunTasks(int num_tasks, int num_threads, const ProgressSink& progress,
              const std::function<void(int i, const ProgressSink& cancellation)>& task,
              const std::function<void(int i)>& done);

}  // namespace omnirig
