// Crash recovery: the real server in a child process is killed with SIGKILL while jobs are
// queued and running, restarted on the same data folder, again and again; then every job must
// reach a terminal state with an intact result, and the database must pass its integrity and
// file/record consistency checks. OMNIRIG_CRASH_CYCLES (default 3) and OMNIRIG_CRASH_JOBS
// (default 8) scale it; bench/load_bench.sh runs 20 cycles.

#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <cstdlib>
#include <random>
#include <thread>

#include "storage/data_dir.h"
#include "storage/sha256.h"
#include "storage/sqlite_job_store.h"
#include "tests/server_test_util.h"

namespace omnirig::testing {
namespace {

using nlohmann::json;

int EnvInt(const char* name, int fallback) {
  const char* value = std::getenv(name);
  return value ? std::atoi(value) : fallback;
}

class CrashTest : public ::testing::Test {
 protected:
  int StartServer(int max_attempts) {
    server_ = std::make_unique<ServerProcess>();
    port_ = server_->Start(
        {"--port", "0", "--data", (dir_.path() / "data").string(), "--workers", "2",
         "--threads-per-job", "1", "--web", "", "--max-attempts", std::to_string(max_attempts)},
        dir_.path() / "server.log");
    client_ = MakeClient(port_);
    return port_;
  }

  std::string Submit(const std::string& dataset) {
    const json params = {{"steps", 10}, {"step_ms", 30}, {"output_kb", 256}};
    const auto result =
        client_->Post("/api/v1/jobs",
                      json{{"type", "test_sleep"}, {"dataset", dataset}, {"params", params}}.dump(),
                      "application/json");
    EXPECT_EQ(result->status, 202);
    return JsonOf(result)["id"];
  }

  // Waits until a job is running and has then made `steps` more progress steps (0-9 of its
  // 10), so the kill hits running and queued jobs at varied points.
  bool WaitForProgressSteps(int steps) {
    int seen = 0;  // events of running jobs
    return FollowEvents(
        port_, "", 60,
        [&] { return steps == 0 && !JsonOf(client_->Get("/api/v1/jobs?state=running")).empty(); },
        [&](const std::string& type, const json& job) {
          if (type != "job" || job["state"] != "running") return false;
          return ++seen > steps;
        });
  }

  void CheckJobIntact(const std::string& id) {
    const json job = JsonOf(client_->Get(("/api/v1/jobs/" + id).c_str()));
    ASSERT_EQ(job["state"], "succeeded") << job.dump();
    const json result = JsonOf(client_->Get(("/api/v1/jobs/" + id + "/result").c_str()));
    EXPECT_EQ(result["steps"], 10);
    EXPECT_EQ(result["output_bytes"], 256 * 1024);
    const std::string expected = SleepJobOutput(256);
    const json artifacts = JsonOf(client_->Get(("/api/v1/jobs/" + id + "/artifacts").c_str()));
    bool found = false;
    for (const json& artifact : artifacts) {
      if (artifact["name"] != "out.bin") continue;
      found = true;
      EXPECT_EQ(artifact["sha256"], storage::Sha256Hex(expected));
      const auto body = client_->Get(("/api/v1/jobs/" + id + "/artifacts/out.bin").c_str());
      EXPECT_EQ(body->body, expected) << "corrupted artifact of job " << id;
    }
    EXPECT_TRUE(found) << "job " << id << " lost its artifact";
  }

  TempDir dir_;
  std::unique_ptr<ServerProcess> server_;
  int port_ = 0;
  std::unique_ptr<httplib::Client> client_;
};

TEST_F(CrashTest, EveryJobSurvivesRepeatedSigkill) {
  const int cycles = EnvInt("OMNIRIG_CRASH_CYCLES", 3);
  const int initial_jobs = EnvInt("OMNIRIG_CRASH_JOBS", 8);
  // Each cycle interrupts a job at most once, so this many attempts always suffice.
  const int max_attempts = cycles + 2;
  std::mt19937 random(42);
  StartServer(max_attempts);
  const std::string dataset =
      JsonOf(client_->Post("/api/v1/datasets", R"({"name": "crash"})", "application/json"))["id"];
  client_->Put(("/api/v1/datasets/" + dataset + "/images/a.png").c_str(), PngBytes(16, 16),
               "image/png");
  std::vector<std::string> jobs;
  for (int i = 0; i < initial_jobs; ++i) jobs.push_back(Submit(dataset));
  for (int cycle = 0; cycle < cycles; ++cycle) {
    if (cycle > 0) {
      StartServer(max_attempts);
      jobs.push_back(Submit(dataset));
      jobs.push_back(Submit(dataset));
    }
    ASSERT_TRUE(WaitForProgressSteps(static_cast<int>(random() % 6))) << "cycle " << cycle;
    server_->Kill(SIGKILL);
    EXPECT_EQ(server_->Wait(), 128 + SIGKILL);
  }
  StartServer(max_attempts);
  int interrupted = 0;
  for (const std::string& id : jobs) {
    const json job = WaitForJob(port_, id, 120);
    ASSERT_EQ(job["state"], "succeeded") << job.dump();
    interrupted += job["attempts"].get<int>() > 1;
    CheckJobIntact(id);
  }
  EXPECT_GE(interrupted, 1) << "no job was running when the server was killed";
  EXPECT_EQ(JsonOf(client_->Get("/api/v1/jobs")).size(), jobs.size());
  EXPECT_EQ(JsonOf(client_->Get("/api/v1/health"))["integrity"], "ok");

  server_->Kill(SIGTERM);
  EXPECT_EQ(server_->Wait(), 0) << "SIGTERM must drain and exit cleanly";
  storage::DataDir data(dir_.path() / "data");
  storage::SqliteJobStore store(data.DatabasePath().string());
  const storage::ConsistencyReport report = storage::CheckConsistency(data, store);
  EXPECT_EQ(report.integrity, "ok");
  EXPECT_TRUE(report.ok());
  EXPECT_TRUE(report.missing_images.empty());
}

TEST_F(CrashTest, JobFailsClearlyAfterMaxAttempts) {
  StartServer(2);
  const std::string dataset =
      JsonOf(client_->Post("/api/v1/datasets", R"({"name": "loop"})", "application/json"))["id"];
  const json params = {{"steps", 1000}, {"step_ms", 20}};
  const std::string id = JsonOf(client_->Post(
      "/api/v1/jobs", json{{"type", "test_sleep"}, {"dataset", dataset}, {"params", params}}.dump(),
      "application/json"))["id"];
  for (int attempt = 0; attempt < 2; ++attempt) {
    if (attempt > 0) StartServer(2);
    ASSERT_EQ(WaitForJob(port_, id, 10, "running")["state"], "running");
    server_->Kill(SIGKILL);
    server_->Wait();
  }
  StartServer(2);
  const json job = JsonOf(client_->Get(("/api/v1/jobs/" + id).c_str()));
  EXPECT_EQ(job["state"], "failed");
  EXPECT_EQ(job["attempts"], 2);
  EXPECT_EQ(job["error"]["code"], "interrupted");
  EXPECT_NE(job["error"]["message"].get<std::string>().find("2 attempts"), std::string::npos);
}

}  // namespace
}  // namespace omnirig::testing

int main(int argc, char** argv) {
  int exit_code = 0;
  if (omnirig::testing::ServeIfRequested(argc, argv, exit_code)) return exit_code;
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
