#pragma once
// Descriptor matching of sparse stereo and SLAM: squared distances and Lowe's ratio test.

#include <limits>

namespace omnirig {

// Squared Euclidean distance of two float descriptors of n entries.
inline float SquaredDescriptorDistance(const float* a, const float* b, int n) {
  float sum = 0.f;
  for (int k = 0; k < n; ++k) {
    const float d = a[k] - b[k];
    sum += d * d;
  }
  return sum;
}

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
