// The shared PostgreSQL goes away while API servers and workers run jobs: stopped and started
// again (StoppedAndStarted) or killed with SIGKILL, server and back-ends, and started again
// with crash recovery (Killed). While it is gone the API answers 503 with Retry-After and a
// JSON error; the servers and workers reconnect by themselves; every job succeeds once, with
// its artifacts intact; no process exits.
//
// The processes: API server A (no workers), server B (one worker of its own), worker W (one
// job at a time), all this binary re-executed (test_sleep registered), on one data folder.

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>

#include <chrono>
#include <fstream>
#include <functional>
#include <set>
#include <sstream>
#include <thread>

#include "server/commands.h"
#include "testing/storage/postgres_test_server.h"
#include "storage/sha256.h"
#include "tests/server_test_util.h"

namespace omnirig::testing {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

constexpr int kJobs = 12;
constexpr int kOutputKb = 32;

std::string ReadText(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

class DatabaseOutageTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const std::string database = pg_.CreateDatabase();
    data_ = dir_.path() / "data";
    const std::vector<std::string> common = {"--database",    database,       "--data",
                                             data_.string(),  "--lease-seconds", "2",
                                             "--max-attempts", "20"};
    std::vector<std::string> a_args = {"--port", "0", "--workers", "0", "--web", ""};
    std::vector<std::string> b_args = {"--port", "0", "--workers", "1", "--threads-per-job", "1",
                                       "--web", ""};
    a_args.insert(a_args.end(), common.begin(), common.end());
    b_args.insert(b_args.end(), common.begin(), common.end());
    port_a_ = server_a_.Start(a_args, dir_.path() / "a.log");
    port_b_ = server_b_.Start(b_args, dir_.path() / "b.log");
    std::vector<std::string> w_args = {"--threads", "1", "--threads-per-job", "1", "--worker-id",
                                       "w"};
    w_args.insert(w_args.end(), common.begin(), common.end());
    const std::string line = worker_.StartChild("--worker", w_args, dir_.path() / "w.log");
    ASSERT_EQ(line.rfind("omnirig worker ", 0), 0u) << line << ReadText(dir_.path() / "w.log");
    a_ = MakeClient(port_a_);
    b_ = MakeClient(port_b_);
  }

  void TearDown() override {
    a_.reset();
    b_.reset();
    for (ServerProcess* process : {&server_a_, &server_b_, &worker_}) {
      if (process->pid() <= 0) continue;
      process->Kill(SIGTERM);
      EXPECT_EQ(process->Wait(), 0);
    }
  }

  // A GET on `client`, asked again while the answer is 503 (the database is still coming back);
  // ctest's timeout is the hang guard.
  json GetRetrying(httplib::Client& client, const std::string& path) {
    while (true) {
      const auto answer = client.Get(path.c_str());
      if (answer && answer->status != 503) {
        EXPECT_EQ(answer->status, 200) << path << ": " << answer->body;
        return JsonOf(answer);
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(20));  // the next poll
    }
  }

  // Every process is still running (none exited on the outage).
  void ExpectAllRunning() {
    for (ServerProcess* process : {&server_a_, &server_b_, &worker_}) {
      int status = 0;
      EXPECT_EQ(::waitpid(process->pid(), &status, WNOHANG), 0)
          << "process " << process->pid() << " exited with status " << status;
    }
  }

  // The API answers 503, Retry-After and a JSON error while the database is gone (a server
  // finds out on its next call; none is cached).
  void ExpectUnavailable(httplib::Client& client, const std::string& dataset,
                         const std::string& job) {
    std::shared_ptr<httplib::Response> answer;
    for (int polls = 0; polls < 100000; ++polls) {  // a hang guard; the first poll is expected
      const auto result = client.Get(("/api/v1/jobs/" + job).c_str());
      ASSERT_TRUE(result) << httplib::to_string(result.error());
      if (result->status == 503) {
        answer = std::make_shared<httplib::Response>(result.value());
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    ASSERT_TRUE(answer) << "never 503";
    EXPECT_EQ(answer->get_header_value("Retry-After"), "1");
    const json error = json::parse(answer->body)["error"];
    EXPECT_EQ(error["code"], "database_unavailable") << answer->body;
    EXPECT_FALSE(error["message"].get<std::string>().empty());
    const auto created = client.Post(
        "/api/v1/jobs",
        json{{"type", "test_sleep"}, {"dataset", dataset}, {"params", {{"steps", 1}}}}.dump(),
        "application/json");
    ASSERT_TRUE(created);
    EXPECT_EQ(created->status, 503) << created->body;
    EXPECT_EQ(json::parse(created->body)["error"]["code"], "database_unavailable");
  }

  // Jobs through both servers; `outage` takes the database away once some have run, and
  // `restore` brings it back after the API was seen answering 503.
  void RunThroughOutage(const std::function<void()>& outage, const std::function<void()>& restore) {
    const std::string dataset = JsonOf(
        a_->Post("/api/v1/datasets", R"({"name": "outage"})", "application/json"))["id"];
    std::vector<std::string> ids;
    const json params = {{"steps", 10}, {"step_ms", 40}, {"output_kb", kOutputKb}};
    for (int i = 0; i < kJobs; ++i) {
      httplib::Client& client = i % 2 ? *b_ : *a_;
      const auto created = client.Post(
          "/api/v1/jobs",
          json{{"type", "test_sleep"}, {"dataset", dataset}, {"params", params}}.dump(),
          "application/json");
      ASSERT_EQ(created->status, 202) << created->body;
      ids.push_back(JsonOf(created)["id"]);
    }
    // The outage comes while jobs run and after at least one has finished.
    while (true) {
      const json jobs = GetRetrying(*a_, "/api/v1/jobs");
      int succeeded = 0, running = 0;
      for (const json& job : jobs) {
        succeeded += job["state"] == "succeeded";
        running += job["state"] == "running" && job["progress"]["fraction"].get<double>() > 0;
      }
      if (succeeded >= 1 && running >= 1) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));  // the next poll
    }
    outage();
    ASSERT_NO_FATAL_FAILURE(ExpectUnavailable(*a_, dataset, ids[0]));
    ASSERT_NO_FATAL_FAILURE(ExpectUnavailable(*b_, dataset, ids[1]));
    ExpectAllRunning();
    restore();

    for (const std::string& id : ids) {
      json job;
      do {
        job = GetRetrying(*a_, "/api/v1/jobs/" + id);
        if (job["state"] == "queued" || job["state"] == "running") {
          std::this_thread::sleep_for(std::chrono::milliseconds(20));  // the next poll
        }
      } while (job["state"] == "queued" || job["state"] == "running");
      ASSERT_EQ(job["state"], "succeeded") << job.dump();
      ASSERT_NO_FATAL_FAILURE(ExpectIntact(job));
    }
    ExpectAllRunning();
    // Everything works as before, through both servers, with no restart.
    for (httplib::Client* client : {a_.get(), b_.get()}) {
      const auto created = client->Post(
          "/api/v1/jobs",
          json{{"type", "test_sleep"}, {"dataset", dataset}, {"params", params}}.dump(),
          "application/json");
      ASSERT_EQ(created->status, 202) << created->body;
      const std::string id = JsonOf(created)["id"];
      json job;
      do {
        job = GetRetrying(*client, "/api/v1/jobs/" + id);
      } while (job["state"] == "queued" || job["state"] == "running");
      EXPECT_EQ(job["state"], "succeeded") << job.dump();
    }
    ExpectAllRunning();
  }

  // The job's artifacts download with their recorded size and sha256, out.bin is what the job
  // wrote, and its folder holds the accepted attempt alone: no other run's end was recorded.
  void ExpectIntact(const json& job) {
    const std::string id = job["id"];
    const json artifacts = JsonOf(a_->Get(("/api/v1/jobs/" + id + "/artifacts").c_str()));
    std::set<std::string> names;
    for (const json& artifact : artifacts) {
      const std::string name = artifact["name"];
      names.insert(name);
      const auto body = a_->Get(("/api/v1/jobs/" + id + "/artifacts/" + name).c_str());
      ASSERT_TRUE(body && body->status == 200) << id << "/" << name;
      EXPECT_EQ(body->body.size(), artifact["size"].get<size_t>()) << id << "/" << name;
      EXPECT_EQ(storage::Sha256Hex(body->body), artifact["sha256"]) << id << "/" << name;
      if (name == "out.bin") {
        EXPECT_EQ(body->body, SleepJobOutput(kOutputKb)) << id;
      }
    }
    EXPECT_TRUE(names.count("out.bin") && names.count("log.txt")) << artifacts.dump();
    // The worker removes the other attempts' folders once the store has accepted the end, so
    // just after the state reads succeeded: wait for that (the deadline guards a hang only).
    const std::set<std::string> expected = {"attempt-" + std::to_string(job["attempts"].get<int>())};
    std::set<std::string> folders;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
    while (true) {
      folders.clear();
      for (const auto& entry : fs::directory_iterator(data_ / "jobs" / id)) {
        folders.insert(entry.path().filename().string());
      }
      if (folders == expected || std::chrono::steady_clock::now() > deadline) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(20));  // the next look
    }
    EXPECT_EQ(folders, expected) << id;
  }

  storage::testing::PostgresTestServer pg_;  // this test's own: it stops and kills it
  TempDir dir_;
  fs::path data_;
  ServerProcess server_a_, server_b_, worker_;
  int port_a_ = 0, port_b_ = 0;
  std::unique_ptr<httplib::Client> a_, b_;
};

TEST_F(DatabaseOutageTest, StoppedAndStarted) {
  RunThroughOutage([&] { pg_.StopServer(); }, [&] { pg_.StartServer(); });
}

TEST_F(DatabaseOutageTest, Killed) {
  RunThroughOutage([&] { pg_.KillServer(); }, [&] { pg_.StartServer(); });
}

}  // namespace
}  // namespace omnirig::testing

int main(int argc, char** argv) {
  int exit_code = 0;
  if (omnirig::testing::ServeIfRequested(argc, argv, exit_code)) return exit_code;
  if (argc >= 2 && std::string(argv[1]) == "--worker") {
    return omnirig::server::WorkerCommand(std::vector<std::string>(argv + 2, argv + argc),
                                          {omnirig::testing::SleepJobType()});
  }
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
