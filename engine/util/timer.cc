#include "engine/util/timer.h"

namespace omnirig {

double Timer::ElapsedSeconds() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

}  // namespace omnirig
