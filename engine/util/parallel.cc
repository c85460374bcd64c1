#include "engine/util/parallel.h"

#include <algorithm>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace omnirig {

void RunTasks(int num_tasks, int num_threads, const ProgressSink& progress,
              const std::function<void(int, const ProgressSink&)>& task,
              const std::function<void(int)>& done) {
  std::mutex mutex;
  int next = 0;
  std::exception_ptr error;
  const ProgressSink cancellation{nullptr, [&mutex, &progress] {
                                    const std::lock_guard<std::mutex> lock(mutex);
                                    return progress.IsCancelled();
                                  }};
  const auto worker = [&] {
    for (;;) {
      int i = 0;
      {
        const std::lock_guard<std::mutex> lock(mutex);
        if (error || next == num_tasks) return;
        i = next++;
      }
      try {
        task(i, cancellation);
        const std::lock_guard<std::mutex> lock(mutex);
        if (done) done(i);
      } catch (...) {
        const std::lock_guard<std::mutex> lock(mutex);
        if (!error) error = std::current_exception();
        return;
      }
    }
  };
  std::vector<std::thread> threads;
  for (int t = 1; t < std::min(num_threads, num_tasks); ++t) threads.emplace_back(worker);
  worker();
  for (std::thread& thread : threads) thread.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace omnirig
