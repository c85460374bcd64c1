#include "engine/util/background_task.h"

#include <utility>

namespace omnirig {

BackgroundTask::~BackgroundTask() {
  if (outstanding_.valid()) outstanding_.wait();
}

void BackgroundTask::Run(std::function<void()> task) {
  Wait();
  outstanding_ = std::async(std::launch::async, std::move(task));
}

void BackgroundTask::Wait() {
  // get() leaves the future invalid, so an error is rethrown once, and a failed task's
  // successor is never started by the Run() that rethrows.
  if (outstanding_.valid()) outstanding_.get();
}

}  // namespace omnirig
