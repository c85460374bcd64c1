#include "engine/util/parallel.h"

#include <gtest/gtest.h>

#include <atomic>
#include <stdexcept>
#include <vector>

namespace omnirig {
namespace {

TEST(RunTasks, EveryTaskRunsOnceWhateverTheThreadCount) {
  for (int threads : {0, 1, 2, 4, 50}) {
    std::vector<int> runs(37, 0);
    int done_calls = 0;
    RunTasks(
        static_cast<int>(runs.size()), threads, ProgressSink{},
        [&](int i, const ProgressSink&) { ++runs[i]; }, [&](int) { ++done_calls; });
    for (int count : runs) EXPECT_EQ(count, 1) << threads << " threads";
    EXPECT_EQ(done_calls, 37);
  }
  RunTasks(0, 2, ProgressSink{}, [](int, const ProgressSink&) { FAIL(); }, nullptr);
}

TEST(RunTasks, FirstErrorStopsNewTasksAndIsRethrown) {
  std::atomic<int> started{0};
  EXPECT_THROW(RunTasks(
                   1000, 1, ProgressSink{},
                   [&](int i, const ProgressSink&) {
                     ++started;
                     if (i == 3) throw std::runtime_error("task 3");
                   },
                   nullptr),
               std::runtime_error);
  EXPECT_EQ(started.load(), 4);  // one thread: tasks 0..3, none after the failure
}

TEST(RunTasks, CancellationReachesTheTasks) {
  int polls = 0;
  const ProgressSink progress{nullptr, [&polls] { return ++polls > 5; }};
  EXPECT_THROW(RunTasks(
                   100, 2, progress,
                   [](int, const ProgressSink& cancellation) { cancellation.ThrowIfCancelled(); },
                   nullptr),
               Cancelled);
  EXPECT_LE(polls, 8);  // stopped soon after the sink said so (at most one poll per thread more)
}

}  // namespace
}  // namespace omnirig
