// Jobs shared by several processes through PostgreSQL: a real PostgreSQL 15, one
// API-only server and `omnirig worker` processes (this binary re-executed, so test_sleep is
// registered), all on one shared data folder.
//
// KillTest: 30 small real calibrations through three workers while a random worker is killed
// with SIGKILL whenever one of its jobs has made progress (after every few finished jobs) and
// restarted; every job must succeed exactly once, with its artifacts intact (sha256) and its
// lost runs counted in `attempts`. StoppedWorker: a worker stopped with SIGSTOP past its lease,
// then continued, must not overwrite the result of the run that took its job over.
// OMNIRIG_MULTI_JOBS (default 30) scales the kill test.

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <thread>

#include "server/commands.h"
#include "storage/sha256.h"
#include "testing/storage/postgres_test_server.h"
#include "tests/server_test_util.h"

namespace omnirig::testing {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

// `omnirig worker` in a child process: this binary with "--worker ARGS...". (A worker stopped
// with SIGSTOP still dies of the SIGKILL ServerProcess's destructor sends.)
class WorkerProcess : public ServerProcess {
 public:
  void Start(const std::vector<std::string>& worker_args, const fs::path& log_path) {
    const std::string line = StartChild("--worker", worker_args, log_path);
    if (line.rfind("omnirig worker ", 0) != 0) {
      throw std::runtime_error("worker did not start: '" + line + "' (see " + log_path.string() +
                               ")");
    }
  }
};

std::string ReadText(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// The job's state as a client polling the API server sees it, once it is `until_state` (or any
// end state when empty). Not WaitForJob's event stream: an API server pushes the changes of its
// own workers only, and here every job runs in another process.
json PollJob(httplib::Client& client, const std::string& id, double timeout_s,
             const std::string& until_state = "") {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::duration<double>(timeout_s);
  json job;
  while (std::chrono::steady_clock::now() < deadline) {
    job = JsonOf(client.Get(("/api/v1/jobs/" + id).c_str()));
    const std::string state = job.value("state", "");
    if (until_state.empty() ? (state == "succeeded" || state == "failed" || state == "canceled")
                            : state == until_state) {
      return job;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  return job;
}

class MultiWorkerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    database_ = storage::testing::SharedPostgresTestServer().CreateDatabase();
    data_ = dir_.path() / "data";
    server_ = std::make_unique<ServerProcess>();
    const int port = server_->Start({"--port", "0", "--data", data_.string(), "--database",
                                     database_, "--workers", "0", "--web", ""},
                                    dir_.path() / "server.log");
    client_ = MakeClient(port);
  }
  void TearDown() override {
    workers_.clear();
    server_->Kill(SIGTERM);
    EXPECT_EQ(server_->Wait(), 0);
  }

  // Starts (or restarts) worker `index` under a new id: "w<index>-<generation>".
  std::string StartWorker(size_t index, const std::vector<std::string>& extra = {}) {
    if (workers_.size() <= index) workers_.resize(index + 1);
    const std::string id = "w" + std::to_string(index) + "-" + std::to_string(++generation_);
    std::vector<std::string> args = {"--database",
                                     database_,
                                     "--data",
                                     data_.string(),
                                     "--threads",
                                     "1",
                                     "--threads-per-job",
                                     "1",
                                     "--worker-id",
                                     id,
                                     "--lease-seconds",
                                     "2"};
    args.insert(args.end(), extra.begin(), extra.end());
    workers_[index] = std::make_unique<WorkerProcess>();
    workers_[index]->Start(args, dir_.path() / (id + ".log"));
    worker_ids_[index] = id;
    return id;
  }

  std::string CreateDataset(const std::string& name) {
    return JsonOf(
        client_->Post("/api/v1/datasets", json{{"name", name}}.dump(), "application/json"))["id"];
  }

  std::string Submit(const json& body) {
    const auto created = client_->Post("/api/v1/jobs", body.dump(), "application/json");
    EXPECT_EQ(created->status, 202) << created->body;
    return JsonOf(created)["id"];
  }

  // Every artifact downloads with its recorded size and sha256, and the job's folder holds only
  // the accepted attempt's output, whose log names that attempt.
  void CheckArtifactsIntact(const json& job) {
    const std::string id = job["id"];
    const int attempts = job["attempts"];
    const json artifacts = JsonOf(client_->Get(("/api/v1/jobs/" + id + "/artifacts").c_str()));
    ASSERT_FALSE(artifacts.empty()) << id;
    for (const json& artifact : artifacts) {
      const std::string name = artifact["name"];
      const auto body = client_->Get(("/api/v1/jobs/" + id + "/artifacts/" + name).c_str());
      ASSERT_TRUE(body && body->status == 200) << id << "/" << name;
      EXPECT_EQ(body->body.size(), artifact["size"].get<size_t>()) << id << "/" << name;
      EXPECT_EQ(storage::Sha256Hex(body->body), artifact["sha256"]) << id << "/" << name;
    }
    std::set<std::string> folders;
    for (const auto& entry : fs::directory_iterator(data_ / "jobs" / id)) {
      folders.insert(entry.path().filename().string());
    }
    EXPECT_EQ(folders, std::set<std::string>{"attempt-" + std::to_string(attempts)}) << id;
    const std::string log =
        ReadText(data_ / "jobs" / id / ("attempt-" + std::to_string(attempts)) / "log.txt");
    EXPECT_NE(log.find("attempt " + std::to_string(attempts) + " "), std::string::npos) << log;
  }

  TempDir dir_;
  std::string database_;
  fs::path data_;
  std::unique_ptr<ServerProcess> server_;
  std::unique_ptr<httplib::Client> client_;
  std::vector<std::unique_ptr<WorkerProcess>> workers_;
  std::map<size_t, std::string> worker_ids_;
  int generation_ = 0;
};

// Board images rendered by `omnirig synth` (small: the test is about the queue, not accuracy).
void RenderBoardImages(const fs::path& out) {
  const char* binary_dir = std::getenv("OMNIRIG_BINARY_DIR");
  const fs::path omnirig = fs::path(binary_dir ? binary_dir : ".") / "server" / "omnirig";
  const std::string command = omnirig.string() +
                              " synth --preset mono-calib --width 480 --height 360 --views 8 "
                              "--supersampling 1 --threads 1 --seed 3 --out " +
                              out.string() + " >/dev/null 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
}

TEST_F(MultiWorkerTest, KilledWorkersLoseNothingAndRunNothingTwice) {
  const char* jobs_env = std::getenv("OMNIRIG_MULTI_JOBS");
  const int num_jobs = jobs_env ? std::atoi(jobs_env) : 30;
  ASSERT_NO_FATAL_FAILURE(RenderBoardImages(dir_.path() / "boards"));
  const std::string dataset = CreateDataset("boards");
  httplib::MultipartFormDataItems items;
  for (const auto& entry : fs::directory_iterator(dir_.path() / "boards")) {
    if (entry.path().extension() != ".png") continue;
    items.push_back(
        {"files", ReadText(entry.path()), entry.path().filename().string(), "image/png"});
  }
  const auto upload = client_->Post(("/api/v1/datasets/" + dataset + "/images").c_str(), items);
  ASSERT_EQ(upload->status, 201) << upload->body;

  for (size_t w = 0; w < 3; ++w) StartWorker(w, {"--max-attempts", "20"});
  const json board = {{"type", "checkerboard"}, {"cols", 8}, {"rows", 6}, {"square_size_mm", 40}};
  std::vector<std::string> ids;
  for (int i = 0; i < num_jobs; ++i) {
    ids.push_back(
        Submit({{"type", "calibration"}, {"dataset", dataset}, {"params", {{"board", board}}}}));
  }

  // Kill a random worker once one of its jobs has made progress, after every 3 finished jobs.
  std::mt19937 random(18);
  std::map<std::string, std::string> killed_while_running;  // job id -> killed worker's id
  int kills = 0, next_kill_at = 2;
  size_t victim = random() % 3;
  // No deadline of its own: a loaded machine runs the jobs slower, and ctest's TIMEOUT stops a
  // run that hangs.
  while (true) {
    const json jobs = JsonOf(client_->Get("/api/v1/jobs"));
    int finished = 0;
    for (const json& job : jobs) finished += job["state"] != "queued" && job["state"] != "running";
    if (finished == num_jobs) break;
    if (finished >= next_kill_at) {
      std::vector<std::string> running_on_victim;
      for (const json& job : jobs) {
        if (job["state"] == "running" && job["worker"] == worker_ids_[victim] &&
            job["progress"]["fraction"].get<double>() > 0) {
          running_on_victim.push_back(job["id"]);
        }
      }
      if (!running_on_victim.empty()) {
        workers_[victim]->Kill(SIGKILL);
        workers_[victim]->Wait();
        for (const auto& id : running_on_victim) killed_while_running[id] = worker_ids_[victim];
        StartWorker(victim, {"--max-attempts", "20"});
        ++kills;
        next_kill_at = finished + 3;
        victim = random() % 3;
      }
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));  // the next status poll
  }
  EXPECT_GE(kills, 3);

  int reruns = 0;
  for (const std::string& id : ids) {
    const json job = JsonOf(client_->Get(("/api/v1/jobs/" + id).c_str()));
    ASSERT_EQ(job["state"], "succeeded") << job.dump();
    ASSERT_NO_FATAL_FAILURE(CheckArtifactsIntact(job));
    const auto killed = killed_while_running.find(id);
    if (killed == killed_while_running.end()) continue;
    // Either the killed worker's end was recorded just before the kill, or the lost run
    // counts as an attempt and another worker finished the job.
    if (job["worker"] != killed->second) {
      EXPECT_GE(job["attempts"].get<int>(), 2) << job.dump();
      ++reruns;
    }
  }
  EXPECT_GE(reruns, 1) << "no kill hit a running job";
  std::cout << num_jobs << " jobs, " << kills << " workers killed, " << reruns
            << " jobs re-run after a kill" << std::endl;
  const json health = JsonOf(client_->Get("/api/v1/health"));
  EXPECT_EQ(health["integrity"], "ok");
}

TEST_F(MultiWorkerTest, StoppedWorkerDoesNotOverwriteTheTakeOver) {
  const std::string dataset = CreateDataset("sleep");
  const std::string stopped_id = StartWorker(0);
  const json params = {{"steps", 150}, {"step_ms", 20}, {"output_kb", 64}};
  const std::string id = Submit({{"type", "test_sleep"}, {"dataset", dataset}, {"params", params}});
  // Stopped once its run has made progress.
  while (true) {
    const json job = PollJob(*client_, id, 30, "running");
    ASSERT_EQ(job["state"], "running");
    if (job["progress"]["fraction"].get<double>() > 0) break;
  }
  workers_[0]->Kill(SIGSTOP);
  const std::string takeover_id = StartWorker(1);
  const json done = PollJob(*client_, id, 60);
  ASSERT_EQ(done["state"], "succeeded") << done.dump();
  EXPECT_EQ(done["worker"], takeover_id);
  EXPECT_EQ(done["attempts"], 2);
  const std::string result = client_->Get(("/api/v1/jobs/" + id + "/result").c_str())->body;
  const json artifacts = JsonOf(client_->Get(("/api/v1/jobs/" + id + "/artifacts").c_str()));

  workers_[0]->Kill(SIGCONT);
  // The continued worker notices (heartbeat or refused end) and stops the stale run.
  const fs::path log = dir_.path() / (stopped_id + ".log");
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (ReadText(log).find("job " + id) == std::string::npos) {
    ASSERT_LT(std::chrono::steady_clock::now(), deadline) << ReadText(log);
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  // Its run has ended once it drains: nothing it could still write is pending.
  workers_[0]->Kill(SIGTERM);
  EXPECT_EQ(workers_[0]->Wait(), 0);
  workers_[0].reset();
  const std::string stopped_log = ReadText(log);
  EXPECT_TRUE(stopped_log.find("lost the lease of job " + id) != std::string::npos ||
              stopped_log.find("end of job " + id + " was refused") != std::string::npos)
      << stopped_log;

  const json after = JsonOf(client_->Get(("/api/v1/jobs/" + id).c_str()));
  EXPECT_EQ(after["state"], "succeeded");
  EXPECT_EQ(after["worker"], takeover_id);
  EXPECT_EQ(after["attempts"], 2);
  EXPECT_EQ(client_->Get(("/api/v1/jobs/" + id + "/result").c_str())->body, result);
  EXPECT_EQ(JsonOf(client_->Get(("/api/v1/jobs/" + id + "/artifacts").c_str())), artifacts);
  ASSERT_NO_FATAL_FAILURE(CheckArtifactsIntact(after));
  const auto out = client_->Get(("/api/v1/jobs/" + id + "/artifacts/out.bin").c_str());
  EXPECT_EQ(out->body, SleepJobOutput(64));
}

// A one-machine (SQLite) service's history moved to PostgreSQL with `omnirig store copy`: the
// PostgreSQL-backed server then serves the same jobs, results and artifacts from the same folder.
TEST_F(MultiWorkerTest, StoreCopyMovesAOneMachineServiceToPostgres) {
  ServerProcess sqlite_server;
  const int port = sqlite_server.Start({"--port", "0", "--data", data_.string(), "--workers", "1",
                                        "--threads-per-job", "1", "--web", ""},
                                       dir_.path() / "sqlite-server.log");
  auto sqlite_client = MakeClient(port);
  const std::string dataset = JsonOf(
      sqlite_client->Post("/api/v1/datasets", R"({"name": "history"})", "application/json"))["id"];
  httplib::MultipartFormDataItems items = {{"files", PngBytes(64, 48), "cam0/a.png", "image/png"}};
  ASSERT_EQ(sqlite_client->Post(("/api/v1/datasets/" + dataset + "/images").c_str(), items)->status,
            201);
  const json params = {{"steps", 2}, {"step_ms", 1}, {"output_kb", 16}};
  const std::string id = JsonOf(sqlite_client->Post(
      "/api/v1/jobs", json{{"type", "test_sleep"}, {"dataset", dataset}, {"params", params}}.dump(),
      "application/json"))["id"];
  const json done = WaitForJob(port, id, 30);
  ASSERT_EQ(done["state"], "succeeded") << done.dump();
  const std::string result = sqlite_client->Get(("/api/v1/jobs/" + id + "/result").c_str())->body;
  sqlite_client.reset();
  sqlite_server.Kill(SIGTERM);
  ASSERT_EQ(sqlite_server.Wait(), 0);

  const char* binary_dir = std::getenv("OMNIRIG_BINARY_DIR");
  const fs::path omnirig = fs::path(binary_dir ? binary_dir : ".") / "server" / "omnirig";
  const std::string copy = omnirig.string() + " store copy --from sqlite:" + data_.string() +
                           " --to " + database_ + " > " + (dir_.path() / "copy.log").string();
  ASSERT_EQ(std::system(copy.c_str()), 0) << ReadText(dir_.path() / "copy.log");
  EXPECT_NE(ReadText(dir_.path() / "copy.log")
                .find("copied 1 dataset(s) with 1 image record(s), "
                      "1 job(s) with 3 artifact record(s)"),
            std::string::npos)
      << ReadText(dir_.path() / "copy.log");

  const json copied = JsonOf(client_->Get(("/api/v1/jobs/" + id).c_str()));
  EXPECT_EQ(copied["state"], "succeeded");
  EXPECT_EQ(copied["params"], params);
  EXPECT_EQ(client_->Get(("/api/v1/jobs/" + id + "/result").c_str())->body, result);
  ASSERT_NO_FATAL_FAILURE(CheckArtifactsIntact(copied));
  EXPECT_EQ(client_->Get(("/api/v1/jobs/" + id + "/artifacts/out.bin").c_str())->body,
            SleepJobOutput(16));
  const json images = JsonOf(client_->Get(("/api/v1/datasets/" + dataset).c_str()))["images"];
  ASSERT_EQ(images.size(), 1u);
  EXPECT_EQ(images[0]["name"], "cam0/a.png");
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
