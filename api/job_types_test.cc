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

// A worker holds the pointer Find gave it while the job runs, and a type may be replaced
// meanwhile: the held entry must not change under it.
TEST(JobTypes, AReplacedTypeStaysValidForWhoeverHoldsIt) {
  JobTypes types;
  types.Add(NamedType("job_types_test", true));
  const JobType* held = types.Find("job_types_test");
  ASSERT_NE(held, nullptr);
  types.Add(NamedType("job_types_test", false));
  EXPECT_EQ(held->name, "job_types_test");
  EXPECT_TRUE(held->reads_images);
  const JobType* current = types.Find("job_types_test");
  ASSERT_NE(current, nullptr);
  EXPECT_NE(current, held);
  EXPECT_FALSE(current->reads_images);
  EXPECT_EQ(types.Names(), std::vector<std::string>{"job_types_test"});
}

TEST(JobTypes, UnknownNamesAreNotFound) {
  JobTypes types;
  EXPECT_EQ(types.Find("no such job type"), nullptr);
}

// The built-in types, each object its own: adding to one changes no other.
TEST(JobTypes, BuiltinTypesAreAddedToTheGivenObjectOnly) {
  JobTypes types;
  AddBuiltinJobTypes(&types);
  EXPECT_EQ(types.Names(), (std::vector<std::string>{"calibration", "relative_pose", "slam",
                                                     "stereo_reconstruct"}));
  JobTypes other;
  EXPECT_TRUE(other.Names().empty());
}

}  // namespace
}  // namespace omnirig::api
