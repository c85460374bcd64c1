#include "api/job_types.h"

#include <gtest/gtest.h>

namespace omnirig::api {
namespace {

JobType NamedType(const std::string& name, bool reads_images) {
  JobType type;
  type.name = name;
  type.reads_images = reads_images;
  return type;
}

// A worker holds the pointer FindJobType gave it while the job runs; the service registers the
// built-in types again whenever one is constructed. The held entry must not change under it.
TEST(JobTypes, AReplacedTypeStaysValidForWhoeverHoldsIt) {
  RegisterJobType(NamedType("job_types_test", true));
  const JobType* held = FindJobType("job_types_test");
  ASSERT_NE(held, nullptr);
  RegisterJobType(NamedType("job_types_test", false));
  EXPECT_EQ(held->name, "job_types_test");
  EXPECT_TRUE(held->reads_images);
  const JobType* current = FindJobType("job_types_test");
  ASSERT_NE(current, nullptr);
  EXPECT_NE(current, held);
  EXPECT_FALSE(current->reads_images);
}

TEST(JobTypes, UnknownNamesAreNotFound) {
  EXPECT_EQ(FindJobType("no such job type"), nullptr);
}

}  // namespace
}  // namespace omnirig::api
