#include "api/service_json.h"

#include <gtest/gtest.h>

#include "engine/util/check.h"

namespace omnirig::api {
namespace {

void ExpectRefused(const std::string& body, const std::string& needle) {
  try {
    ParseCreateJobRequest(body);
    ADD_FAILURE() << "accepted " << body;
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

TEST(ServiceJson, ParsesJobRequest) {
  const CreateJobRequest request =
      ParseCreateJobRequest(R"({"type": "calibration", "dataset": "d1", "params": {"x": 1}})");
  EXPECT_EQ(request.type, "calibration");
  EXPECT_EQ(request.dataset, "d1");
  EXPECT_EQ(request.params["x"], 1);
  EXPECT_TRUE(ParseCreateJobRequest(R"({"type": "t", "dataset": "d"})").params.is_object());
}

TEST(ServiceJson, RefusesBadJobRequests) {
  ExpectRefused("{not json", "malformed JSON");
  ExpectRefused("[1, 2]", "JSON object");
  ExpectRefused(R"({"type": "t", "dataset": "d", "colour": 1})", "'colour'");
  ExpectRefused(R"({"type": 3, "dataset": "d"})", "'type'");
  ExpectRefused(R"({"type": "t"})", "'dataset'");
  ExpectRefused(R"({"type": "t", "dataset": "d", "params": [1]})", "'params'");
  // A number beyond a double's range is nlohmann's out_of_range, not a parse_error (found by
  // fuzz/service_json_fuzzer.cc): refused as malformed, not escaping as a 500.
  ExpectRefused(R"({"type": "t", "dataset": "d", "params": {"x": 1e999}})", "malformed JSON");
  EXPECT_THROW(ParseCreateDatasetRequest(R"({"name": -1e999})"), InvalidArgument);
}

TEST(ServiceJson, JsonTextReplacesInvalidUtf8) {
  // An error message quoting a request's bytes (here a Content-Range header of Latin-1 bytes):
  // dump() throws on them, which would turn the 400 into a 500 without a JSON body.
  const nlohmann::json error = ErrorJson("invalid_argument", "got 'bytes \xff-\xe9/1'");
  EXPECT_THROW((void)error.dump(), nlohmann::json::type_error);
  const std::string text = JsonText(error);
  EXPECT_EQ(text.find('\xff'), std::string::npos);
  EXPECT_NE(text.find("bytes \xef\xbf\xbd-\xef\xbf\xbd/1"), std::string::npos) << text;
  EXPECT_EQ(nlohmann::json::parse(text)["error"]["code"], "invalid_argument");
  EXPECT_EQ(JsonText({{"a", 1}}), R"({"a":1})");
}

TEST(ServiceJson, DatasetRequest) {
  EXPECT_EQ(ParseCreateDatasetRequest(R"({"name": "rig"})").name, "rig");
  EXPECT_THROW(ParseCreateDatasetRequest(R"({"name": ""})"), InvalidArgument);
  EXPECT_THROW(ParseCreateDatasetRequest(R"({"name": "a", "b": 1})"), InvalidArgument);
  EXPECT_THROW(ParseCreateDatasetRequest(R"({"name": 5})"), InvalidArgument);
}

TEST(ServiceJson, ErrorAndTime) {
  const auto error = ErrorJson("not_found", "no such job");
  EXPECT_EQ(error["error"]["code"], "not_found");
  EXPECT_TRUE(error["error"]["details"].is_object());
  EXPECT_EQ(TimeJson(0.25), "1970-01-01T00:00:00.250Z");
  EXPECT_EQ(TimeJson(1795272229.5), "2026-11-21T14:43:49.500Z");
  EXPECT_TRUE(TimeJson(std::nullopt).is_null());
}

}  // namespace
}  // namespace omnirig::api
