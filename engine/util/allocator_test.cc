#include "engine/util/allocator.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <new>
#include <vector>

namespace omnirig {
namespace {

TEST(LargeArrayAllocator, VectorsKeepTheirValuesAcrossTheLargeBlockThreshold) {
  // Grows from heap blocks into mapped ones and back down (shrink_to_fit), the values kept.
  std::vector<uint64_t, LargeArrayAllocator<uint64_t>> values;
  const size_t large = 3 * kLargeBlockBytes / sizeof(uint64_t);
  for (size_t i = 0; i < large; ++i) values.push_back(i * 2654435761u);
  for (size_t i = 0; i < large; i += 4099) ASSERT_EQ(values[i], i * 2654435761u) << i;
  EXPECT_EQ(values.back(), (large - 1) * 2654435761u);
  values.resize(100);
  values.shrink_to_fit();
  for (size_t i = 0; i < values.size(); ++i) ASSERT_EQ(values[i], i * 2654435761u) << i;
}

TEST(LargeArrayAllocator, NewLargeBlocksAreZeroAndWritable) {
  std::vector<int32_t, LargeArrayAllocator<int32_t>> zeros(2 * kLargeBlockBytes / 4);
  int64_t sum = 0;
  for (int32_t v : zeros) sum += v;
  EXPECT_EQ(sum, 0);
  zeros.assign(zeros.size(), 7);
  EXPECT_EQ(zeros.front() + zeros.back(), 14);
}

TEST(LargeArrayAllocator, ASizeBeyondTheAddressSpaceThrowsBadAlloc) {
  LargeArrayAllocator<uint64_t> allocator;
  EXPECT_THROW(allocator.allocate(static_cast<size_t>(-1) / 4), std::bad_alloc);
}

}  // namespace
}  // namespace omnirig
