#include "api/sample_params.h"

#include <gtest/gtest.h>

#include "engine/util/check.h"

namespace omnirig::api {
namespace {

using nlohmann::json;

TEST(SampleParams, NamesThePreset) {
  EXPECT_EQ(SamplePresetFromJson({{"preset", "stereo-board"}}), "stereo-board");
}

TEST(SampleParams, RefusesBadParamsWithInvalidArgument) {
  // A preset of another type than a string once escaped as nlohmann's type_error (a 500).
  for (const json& params : {json{{"preset", 5}}, json{{"preset", nullptr}},
                             json{{"preset", json::array()}}, json::object(),
                             json{{"preset", "mono"}}, json{{"preset", "mono-calib"}, {"x", 1}},
                             json::array()}) {
    EXPECT_THROW(SamplePresetFromJson(params), InvalidArgument) << params;
  }
}

}  // namespace
}  // namespace omnirig::api
