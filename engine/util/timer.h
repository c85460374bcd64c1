#pragma once

#include <chrono>

namespace omnirig {

// Wall-clock stopwatch for the timings that reports carry.
class Timer {
 public:
  Timer() : start_(std::chrono::steady_clock::now()) {}
  void Restart() { start_ = std::chrono::steady_clock::now(); }
  double ElapsedSeconds() const;

 private:
  std::chrono::steady_clock::time_point start_;
};

}  // namespace omnirig
