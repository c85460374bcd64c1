#pragma once
// Descriptor matching of sparse stereo and SLAM: Lowe's ratio test.

#include <limits>

namespace omnirig {

// The best and second-best squared descriptor distances among one feature's candidates.
struct BestTwo {
  int best = -1;  // the best candidate's index; -1 while none
  float d1 = std::numeric_limits<float>::infinity();
  float d2 = std::numeric_limits<float>::infinity();
  void Add(int index, float squared_distance) {
    if (squared_distance < d1) {
      d2 = d1;
      d1 = squared_distance;
      best = index;
    } else if (squared_distance < d2) {
      d2 = squared_distance;
    }
  }
  // Lowe's ratio on distances (squared distances compare with ratio^2); a lone candidate passes.
  bool PassesRatio(double ratio) const { return best >= 0 && d1 < ratio * ratio * d2; }
};

}  // namespace omnirig
