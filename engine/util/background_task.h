#pragma once
// One task at a time on a background thread, so that a job can write one piece of work's
// outputs while it computes the next (dense stereo: pair k's PLY, TIFF and PNG are written while
// pair k + 1 is matched; the writing runs on one thread, the matching on all).

#include <functional>
#include <future>

namespace omnirig {

// Tasks run in the order given, never two at once, and at most one is outstanding: Run() waits
// for the previous task before starting the next, so the caller holds at most one task's inputs
// besides its own work (a bounded queue of one).
class BackgroundTask {
 public:
  BackgroundTask() = default;
  BackgroundTask(const BackgroundTask&) = delete;
  BackgroundTask& operator=(const BackgroundTask&) = delete;
  // Waits for the outstanding task. An error it threw is dropped: the owner is unwinding from
  // an error of its own (or a cancellation) that the caller sees instead.
  ~BackgroundTask();

  // Waits for the outstanding task and rethrows its exception (then `task` is not started);
  // otherwise starts `task` on a new thread and returns.
  void Run(std::function<void()> task);

  // Waits for the outstanding task and rethrows its exception. Call it before using what the
  // tasks produced.
  void Wait();

 private:
  std::future<void> outstanding_;
};

}  // namespace omnirig
