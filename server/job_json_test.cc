// The job JSON written without a tree (job_json.h) against the tree form it replaced on the
// hot routes (JobJson below, the readable spec of json_views.h's job form): the same bytes for
// every kind of record.

#include "server/job_json.h"

#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "api/service_json.h"

namespace omnirig::server {
namespace {

// The job as nlohmann builds it: the oracle job_json.cc must match byte for byte.
nlohmann::json JobJson(const storage::JobRecord& job) {
  nlohmann::json params = nlohmann::json::parse(job.params, nullptr, false);
  nlohmann::json json = {
      {"id", job.id},
      {"type", job.type},
      {"dataset", job.dataset_id},
      {"params", params.is_discarded() ? nlohmann::json(nullptr) : params},
      {"state", storage::JobStateName(job.state)},
      {"progress",
       {{"fraction", job.progress.fraction},
        {"stage", job.progress.stage},
        {"message", job.progress.message},
        {"eta_s", job.progress.eta_s ? nlohmann::json(*job.progress.eta_s) : nullptr}}},
      {"created_at", api::TimeJson(job.created_at)},
      {"started_at", api::TimeJson(job.started_at)},
      {"finished_at", api::TimeJson(job.finished_at)},
      {"attempts", job.attempts},
      {"cancel_requested", job.cancel_requested},
      {"worker", job.worker_id.empty() ? nlohmann::json(nullptr) : nlohmann::json(job.worker_id)},
      {"error", nullptr}};
  if (job.error) json["error"] = {{"code", job.error->code}, {"message", job.error->message}};
  return json;
}


storage::JobRecord QueuedJob() {
  storage::JobRecord job;
  job.id = "0123456789abcdef";
  job.type = "calibration";
  job.dataset_id = "fedcba9876543210";
  job.params = nlohmann::json::parse(
                   R"({"board": {"type": "checkerboard", "cols": 6, "rows": 7,
                       "square_size_mm": 30.5}, "options": [1, -2, 3.25e-9, null, true]})")
                   .dump();
  job.created_at = 1795312345.678;
  return job;
}

storage::JobRecord FailedJob() {
  storage::JobRecord job = QueuedJob();
  job.state = storage::JobState::kFailed;
  job.started_at = 1795312346.001;
  job.finished_at = 1795312399.999;
  job.attempts = 3;
  job.cancel_requested = true;
  job.worker_id = "rig-02.lab:4711";
  job.progress = {0.5, "detect", "VMRImage1.jpg: found", 12.25};
  job.error = storage::JobError{
      "invalid_input",
      "calibration needs at least 3 usable views, got 2:\n  \"a\\b\"\t\x01\x1f\x7f"};
  return job;
}

TEST(JobJsonTest, QueuedAndFailedJobsMatchTheTreeForm) {
  for (const storage::JobRecord& job : {QueuedJob(), FailedJob()}) {
    EXPECT_EQ(JobJsonText(job), JobJson(job).dump());
  }
}

TEST(JobJsonTest, EveryStateMatches) {
  storage::JobRecord job = FailedJob();
  for (const auto state :
       {storage::JobState::kQueued, storage::JobState::kRunning, storage::JobState::kSucceeded,
        storage::JobState::kFailed, storage::JobState::kCanceled}) {
    job.state = state;
    EXPECT_EQ(JobJsonText(job), JobJson(job).dump());
  }
}

TEST(JobJsonTest, ParamsThatAreNotJsonBecomeNull) {
  storage::JobRecord job = QueuedJob();
  for (const std::string params : {"", "{", "{\"a\": }", "nan", "{} {}"}) {
    job.params = params;
    EXPECT_EQ(JobJsonText(job), JobJson(job).dump()) << params;
    EXPECT_TRUE(nlohmann::json::parse(JobJsonText(job))["params"].is_null()) << params;
  }
}

// Text CreateJob did not write (another store's formatting): same content, spliced as stored.
TEST(JobJsonTest, ParamsInAnotherLayoutKeepTheirContent) {
  storage::JobRecord job = QueuedJob();
  job.params = "{ \"b\" : [1, 2],\n \"a\" : {\"x\": \"y\"} }";
  const nlohmann::json text = nlohmann::json::parse(JobJsonText(job));
  EXPECT_EQ(text, nlohmann::json::parse(JobJson(job).dump()));
}

TEST(JobJsonTest, StringsEscapeAsNlohmannDoes) {
  std::string every_ascii;
  for (int c = 1; c < 0x80; ++c) every_ascii += static_cast<char>(c);
  for (const std::string& value :
       {std::string(), every_ascii, std::string("caf\xc3\xa9 \xe2\x9c\x93 \xf0\x9f\x98\x80"),
        std::string("tail\\"), std::string("\"")}) {
    std::string out;
    AppendJsonString(value, out);
    EXPECT_EQ(out, nlohmann::json(value).dump());
  }
  // Invalid UTF-8 fails as before (the request becomes a 500, not a corrupt body).
  std::string out;
  EXPECT_THROW(AppendJsonString("bad \xff byte", out), nlohmann::json::type_error);
  storage::JobRecord job = QueuedJob();
  job.progress.message = "bad \xc3";
  EXPECT_THROW(JobJsonText(job), nlohmann::json::type_error);
  EXPECT_THROW(JobJson(job).dump(), nlohmann::json::type_error);
}

TEST(JobJsonTest, NumbersMatch) {
  std::mt19937_64 random(17);
  std::vector<double> values = {0.0,
                                -0.0,
                                1.0,
                                0.1,
                                1.0 / 3,
                                1e-7,
                                123456789.0,
                                1e21,
                                1e22,
                                -2.5,
                                0.999,
                                5e-324,
                                1.7976931348623157e308,
                                std::numeric_limits<double>::quiet_NaN(),
                                std::numeric_limits<double>::infinity(),
                                -std::numeric_limits<double>::infinity()};
  std::uniform_real_distribution<double> unit(0, 1);
  std::uniform_int_distribution<uint64_t> bits;
  for (int i = 0; i < 2000; ++i) {
    values.push_back(unit(random));
    uint64_t raw = bits(random);
    double any;
    std::memcpy(&any, &raw, sizeof(any));
    values.push_back(any);
  }
  for (const double value : values) {
    std::string out;
    AppendJsonNumber(value, out);
    ASSERT_EQ(out, nlohmann::json(value).dump()) << value;
  }
}

TEST(JobJsonTest, TimesMatchTimeJson) {
  std::mt19937_64 random(29);
  std::vector<double> times = {0.0,
                               -0.001,
                               0.9999,
                               951782400.0 /* 2000-02-29 */,
                               -86400.5,
                               4102444800.0,
                               253402300799.999,
                               -30610224000.0,
                               -62167219200.0 /* year 0: strftime's path */,
                               253402300800.0 /* year 10000 */};
  std::uniform_real_distribution<double> modern(0, 4.2e9), wide(-3.0e10, 2.5e11);
  for (int i = 0; i < 5000; ++i) {
    times.push_back(modern(random));
    times.push_back(wide(random));
  }
  for (const double time : times) {
    std::string out;
    AppendJsonTime(time, out);
    ASSERT_EQ(out, api::TimeJson(time).dump()) << std::fixed << time;
  }
  std::string out;
  AppendJsonTime(std::nullopt, out);
  EXPECT_EQ(out, "null");
}

TEST(JobJsonTest, ListIsAnArrayOfTheJobs) {
  EXPECT_EQ(JobListJsonText({}), "[]");
  nlohmann::json expected = nlohmann::json::array();
  std::vector<storage::JobRecord> jobs = {QueuedJob(), FailedJob(), QueuedJob()};
  for (const auto& job : jobs) expected.push_back(JobJson(job));
  EXPECT_EQ(JobListJsonText(jobs), expected.dump());
}

}  // namespace
}  // namespace omnirig::server
