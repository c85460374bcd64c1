// JobEvents on a real SQLite store: the SSE text of a change, per-job streams, deleted jobs,
// a stream that falls behind, and Close().

#include "server/events.h"

#include <unistd.h>

#include <filesystem>
#include <random>
#include <string>
#include <thread>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "storage/data_dir.h"
#include "storage/sqlite_job_store.h"

namespace omnirig::server {
namespace {

using nlohmann::json;

class JobEventsTest : public ::testing::Test {
 protected:
  JobEventsTest()
      : root_(std::filesystem::temp_directory_path() /
              ("omnirig-events-test-" + std::to_string(::getpid()) + "-" +
               std::to_string(std::random_device()()))),
        data_dir_(root_),
        store_(data_dir_.DatabasePath().string()),
        events_(store_) {
    dataset_ = store_.CreateDataset("events").id;
  }
  ~JobEventsTest() override {
    std::error_code ignored;
    std::filesystem::remove_all(root_, ignored);
  }

  std::string NewJob() { return store_.CreateJob("sleep", dataset_, "{\"steps\":1}").id; }

  std::filesystem::path root_;
  storage::DataDir data_dir_;
  storage::SqliteJobStore store_;
  JobEvents events_;
  std::string dataset_;
};

// The events in SSE text: (event type, data JSON) each.
std::vector<std::pair<std::string, json>> Parse(const std::string& text) {
  std::vector<std::pair<std::string, json>> parsed;
  size_t at = 0;
  while (at < text.size()) {
    const size_t end = text.find("\n\n", at);
    if (end == std::string::npos) break;
    const std::string block = text.substr(at, end - at);
    at = end + 2;
    const size_t event = block.find("event: ");
    const size_t data = block.find("data: ");
    if (block.rfind("id: ", 0) != 0 || event == std::string::npos || data == std::string::npos) {
      ADD_FAILURE() << "not an event: " << block;
      continue;
    }
    parsed.emplace_back(block.substr(event + 7, block.find('\n', event) - event - 7),
                        json::parse(block.substr(data + 6)));
  }
  return parsed;
}

TEST_F(JobEventsTest, AStreamGetsEachChangeAsTheJobNowIs) {
  const std::string before = NewJob();
  events_.Changed(before);  // no stream open: nothing is kept
  JobEvents::Stream stream(events_, std::nullopt);
  const std::string id = NewJob();
  events_.Changed(id);
  store_.ClaimNextJob({});  // `before`, the oldest
  store_.UpdateProgress(before, {0.25, "sleep", "step 1", 3.0});
  events_.Changed(before);
  std::string text;
  ASSERT_TRUE(stream.Next(text, 1000));
  const auto parsed = Parse(text);
  ASSERT_EQ(parsed.size(), 2u) << text;
  EXPECT_EQ(parsed[0].first, "job");
  EXPECT_EQ(parsed[0].second["id"], id);
  EXPECT_EQ(parsed[0].second["state"], "queued");
  EXPECT_EQ(parsed[0].second["params"], json({{"steps", 1}}));
  EXPECT_EQ(parsed[1].second["id"], before);
  EXPECT_EQ(parsed[1].second["state"], "running");
  EXPECT_EQ(parsed[1].second["progress"]["fraction"], 0.25);
  EXPECT_EQ(parsed[1].second["progress"]["stage"], "sleep");
  // Nothing new: Next() returns after its wait with nothing added.
  text.clear();
  ASSERT_TRUE(stream.Next(text, 10));
  EXPECT_EQ(text, "");
}

TEST_F(JobEventsTest, APerJobStreamSkipsOtherJobsAndSeesDeletion) {
  const std::string followed = NewJob();
  const std::string other = NewJob();
  JobEvents::Stream stream(events_, followed);
  events_.Changed(other);
  events_.Changed(followed);
  ASSERT_TRUE(store_.DeleteJob(followed));
  events_.Changed(followed);
  std::string text;
  ASSERT_TRUE(stream.Next(text, 1000));
  const auto parsed = Parse(text);
  ASSERT_EQ(parsed.size(), 2u) << text;
  EXPECT_EQ(parsed[0].second["id"], followed);
  EXPECT_EQ(parsed[1].first, "job_deleted");
  EXPECT_EQ(parsed[1].second, json({{"id", followed}}));
}

TEST_F(JobEventsTest, AStreamFarBehindKeepsTheNewestEvents) {
  const std::string id = NewJob();
  JobEvents::Stream stream(events_, std::nullopt);
  for (size_t i = 0; i < JobEvents::kBacklog + 10; ++i) events_.Changed(id);
  std::string text;
  ASSERT_TRUE(stream.Next(text, 1000));
  EXPECT_EQ(Parse(text).size(), JobEvents::kBacklog);
  events_.Changed(id);
  text.clear();
  ASSERT_TRUE(stream.Next(text, 1000));
  EXPECT_EQ(Parse(text).size(), 1u);
}

TEST_F(JobEventsTest, CloseEndsAWaitingStream) {
  JobEvents::Stream stream(events_, std::nullopt);
  std::thread closer([this] { events_.Close(); });
  std::string text;
  // Waits (for as long as it takes, not a fixed time) until Close() wakes it.
  while (stream.Next(text, 60000)) {
  }
  closer.join();
  EXPECT_EQ(text, "");
}

}  // namespace
}  // namespace omnirig::server
