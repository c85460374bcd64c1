#include "engine/util/background_task.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <future>
#include <stdexcept>
#include <thread>
#include <vector>

namespace omnirig {
namespace {

TEST(BackgroundTask, RunsTasksInOrderOneAtATime) {
  std::vector<int> order;  // written by the tasks only: one at a time, so without a lock
  std::atomic<int> running{0};
  std::atomic<int> most_running{0};
  {
    BackgroundTask background;
    for (int i = 0; i < 20; ++i) {
      background.Run([&, i] {
        most_running = std::max(most_running.load(), ++running);
        std::this_thread::yield();
        order.push_back(i);
        --running;
      });
    }
    background.Wait();
    ASSERT_EQ(order.size(), 20u);
  }
  for (int i = 0; i < 20; ++i) EXPECT_EQ(order[i], i);
  EXPECT_EQ(most_running.load(), 1);
}

TEST(BackgroundTask, RunDoesNotWaitForItsOwnTask) {
  std::promise<void> release;
  std::shared_future<void> released = release.get_future().share();
  std::atomic<bool> done{false};
  BackgroundTask background;
  background.Run([&] {
    released.wait();  // holds until the caller, having returned from Run, releases it
    done = true;
  });
  EXPECT_FALSE(done.load());
  release.set_value();
  background.Wait();
  EXPECT_TRUE(done.load());
}

TEST(BackgroundTask, AnErrorIsRethrownOnceAndStopsTheNextTask) {
  BackgroundTask background;
  bool second_ran = false;
  background.Run([] { throw std::runtime_error("cannot write a.ply"); });
  try {
    background.Run([&] { second_ran = true; });
    ADD_FAILURE() << "expected the first task's error";
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "cannot write a.ply");
  }
  background.Wait();  // nothing outstanding: the error was reported once
  EXPECT_FALSE(second_ran);
  background.Run([&] { second_ran = true; });  // usable again
  background.Wait();
  EXPECT_TRUE(second_ran);
}

TEST(BackgroundTask, DestructorWaitsForTheOutstandingTask) {
  std::atomic<bool> done{false};
  {
    BackgroundTask background;
    background.Run([&] {
      for (int i = 0; i < 10000; ++i) std::this_thread::yield();  // outlive the scope's end
      done = true;
    });
  }
  EXPECT_TRUE(done.load());
  {
    BackgroundTask background;  // an outstanding error is dropped, not thrown from the destructor
    background.Run([] { throw std::runtime_error("dropped"); });
  }
}

}  // namespace
}  // namespace omnirig
