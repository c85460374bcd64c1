#pragma once
// One-line checks of an options field, with one wording for every option (the API returns it
// as the 400 text): "NAME must lie in (lo, hi], got X", "NAME must be positive, got X",
// "NAME must not be negative, got X", "NAME must be at least N, got X". NAME is the field as
// written in the call, so it is the C++ (and JSON) name. A floating-point field must also be
// finite: NaN fails every comparison, and no option has a meaning at infinity.

#include <cmath>
#include <type_traits>

#include "engine/util/check.h"

namespace omnirig::internal {

template <typename T>
bool IsFiniteOption(T value) {
  if constexpr (std::is_floating_point_v<T>) {
    return std::isfinite(value);
  } else {
    return true;
  }
}

// `open` is '(' or '[' and `close` is ')' or ']', as the interval is written.
template <typename T>
bool InInterval(T value, char open, double lo, double hi, char close) {
  const bool above = open == '(' ? value > lo : value >= lo;
  const bool below = close == ')' ? value < hi : value <= hi;
  return above && below;
}

}  // namespace omnirig::internal

#define OMNIRIG_CHECK_OPTION_(ok, x, requirement)               \
  OMNIRIG_CHECK((ok) && ::omnirig::internal::IsFiniteOption(x), \
                #x " must " << requirement << ", got " << (x))

// OMNIRIG_CHECK_IN(max_parallax_deg, '(', 0, 45, ']'): 0 < max_parallax_deg <= 45.
#define OMNIRIG_CHECK_IN(x, open, lo, hi, close)                                    \
  OMNIRIG_CHECK_OPTION_(::omnirig::internal::InInterval(x, open, lo, hi, close), x, \
                        "lie in " << (open) << (lo) << ", " << (hi) << (close))
#define OMNIRIG_CHECK_POSITIVE(x) OMNIRIG_CHECK_OPTION_((x) > 0, x, "be positive")
#define OMNIRIG_CHECK_NON_NEGATIVE(x) OMNIRIG_CHECK_OPTION_((x) >= 0, x, "not be negative")
#define OMNIRIG_CHECK_AT_LEAST(x, lo) OMNIRIG_CHECK_OPTION_((x) >= (lo), x, "be at least " << (lo))
