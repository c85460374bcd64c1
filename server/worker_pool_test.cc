// The worker pool on a real SQLite store and data folder: a job runs to its result and every
// change is reported, a cancel stops a running job, a drain hands it back to the queue, and the
// worker threads run at normal priority unless told otherwise. A test job type holds its run at
// a gate the test opens, so the test waits on events, never on time.

#include "server/worker_pool.h"

#include <sched.h>
#include <sys/resource.h>
#include <unistd.h>

#include <chrono>
#include <condition_variable>
#include <filesystem>
#include <map>
#include <mutex>
#include <random>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "api/job_types.h"
#include "engine/geometry/ply.h"
#include "storage/sqlite_job_store.h"

namespace omnirig::server {
namespace {

using nlohmann::json;

// The gate the "pool_test_gate" jobs wait at (checking their cancel flag) after reporting half
// their progress.
struct Gate {
  std::mutex mutex;
  std::condition_variable changed;
  bool open = false;
};
Gate gate;

api::JobType GateJobType() {
  api::JobType type;
  type.name = "pool_test_gate";
  type.reads_images = false;
  type.validate = [](const json&) {};
  type.run = [](const json&, const api::JobContext& context) {
    context.progress.Report(0.5, "wait", "at the gate");
    {
      std::unique_lock<std::mutex> lock(gate.mutex);
      while (!gate.open) {
        context.progress.ThrowIfCancelled();
        gate.changed.wait_for(lock, std::chrono::milliseconds(5));
      }
    }
    context.progress.Report(1.0, "done");
    return json{{"nice", ::getpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()))},
                {"sched_other", ::sched_getscheduler(0) == SCHED_OTHER},
                {"threads", context.num_threads}};
  };
  return type;
}

// Writes a large cloud (1.5 million points, 22.5 MB) and a small one, as the dense and slam jobs
// write theirs.
api::JobType CloudJobType() {
  api::JobType type;
  type.name = "pool_test_cloud";
  type.reads_images = false;
  type.validate = [](const json&) {};
  type.run = [](const json&, const api::JobContext& context) {
    PlyCloud cloud;
    for (int i = 0; i < 1'500'000; ++i) {
      cloud.positions.emplace_back(static_cast<float>(i % 1000), static_cast<float>(i / 1000),
                                   0.0f);
      cloud.colours.push_back({static_cast<uint8_t>(i), 0, 0});
    }
    std::filesystem::create_directories(context.output_dir / "pairs");
    WritePly(context.output_dir / "pairs" / "cloud.ply", cloud);
    cloud.positions.resize(10);
    cloud.colours.resize(10);
    WritePly(context.output_dir / "small.ply", cloud);
    return json{{"artifact", "pairs/cloud.ply"}};
  };
  return type;
}

class WorkerPoolTest : public ::testing::Test {
 protected:
  WorkerPoolTest()
      : root_(std::filesystem::temp_directory_path() /
              ("omnirig-pool-test-" + std::to_string(::getpid()) + "-" +
               std::to_string(std::random_device()()))),
        data_dir_(root_),
        store_(data_dir_.DatabasePath().string()) {
    job_types_.Add(GateJobType());
    job_types_.Add(CloudJobType());
    SetGate(false);
    dataset_ = store_.CreateDataset("pool").id;
  }
  ~WorkerPoolTest() override {
    SetGate(true);
    pool_.reset();
    std::error_code ignored;
    std::filesystem::remove_all(root_, ignored);
  }

  static void SetGate(bool open) {
    std::lock_guard<std::mutex> lock(gate.mutex);
    gate.open = open;
    gate.changed.notify_all();
  }

  WorkerPool& StartPool(WorkerPoolOptions options = {}) {
    options.threads_per_job = 2;
    options.progress_interval_s = 0;
    options.on_job_changed = [this](const std::string& id) {
      std::lock_guard<std::mutex> lock(mutex_);
      const auto job = store_.GetJob(id);
      changes_.push_back(job ? std::string(storage::JobStateName(job->state)) + " " +
                                   std::to_string(job->progress.fraction)
                             : "deleted");
      changed_.notify_all();
    };
    pool_ = std::make_unique<WorkerPool>(store_, data_dir_, job_types_, metrics_, options);
    pool_->Start();
    return *pool_;
  }

  std::string Submit(const std::string& type = "pool_test_gate") {
    const std::string id = store_.CreateJob(type, dataset_, "{}").id;
    if (pool_) pool_->Notify();
    return id;
  }

  // Waits until the pool has reported `change` ("running 0.500000", ...).
  void WaitForChange(const std::string& change) {
    std::unique_lock<std::mutex> lock(mutex_);
    changed_.wait(lock, [&] {
      return std::find(changes_.begin(), changes_.end(), change) != changes_.end();
    });
  }

  storage::JobRecord Job(const std::string& id) { return *store_.GetJob(id); }

  std::filesystem::path root_;
  storage::DataDir data_dir_;
  storage::SqliteJobStore store_;
  Metrics metrics_;
  api::JobTypes job_types_;
  std::string dataset_;
  std::unique_ptr<WorkerPool> pool_;
  std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<std::string> changes_;
};

TEST_F(WorkerPoolTest, RunsAJobToItsResultAndReportsEachChange) {
  WorkerPool& pool = StartPool();
  const std::string id = Submit();
  WaitForChange("running 0.500000");
  EXPECT_EQ(pool.busy(), 1);
  SetGate(true);
  WaitForChange("succeeded 1.000000");
  const storage::JobRecord job = Job(id);
  EXPECT_EQ(job.state, storage::JobState::kSucceeded);
  EXPECT_EQ(job.attempts, 1);
  const json result = json::parse(*store_.GetResult(id));
  EXPECT_EQ(result["threads"], 2);
  std::set<std::string> artifacts;
  for (const auto& artifact : store_.ListArtifacts(id)) artifacts.insert(artifact.name);
  EXPECT_TRUE(artifacts.count("log.txt") && artifacts.count("result.json"));
  // Claimed (running, no progress yet), halfway, done (progress), then finished.
  std::lock_guard<std::mutex> lock(mutex_);
  ASSERT_GE(changes_.size(), 3u);
  EXPECT_EQ(changes_.front(), "running 0.000000");
  EXPECT_EQ(changes_.back(), "succeeded 1.000000");
}

// Every large cloud a job writes gets a preview beside it (NAME.preview.ply, under 2 M points
// and 20 MB), recorded as an artifact with its hash; small clouds get none.
TEST_F(WorkerPoolTest, ALargeCloudGetsAPreviewArtifact) {
  StartPool();
  const std::string id = Submit("pool_test_cloud");
  WaitForChange("succeeded 1.000000");
  std::map<std::string, storage::ArtifactRecord> artifacts;
  for (const auto& artifact : store_.ListArtifacts(id)) artifacts[artifact.name] = artifact;
  ASSERT_TRUE(artifacts.count("pairs/cloud.ply"));
  ASSERT_TRUE(artifacts.count("pairs/cloud.preview.ply"));
  EXPECT_FALSE(artifacts.count("small.preview.ply"));
  const storage::ArtifactRecord& full = artifacts["pairs/cloud.ply"];
  const storage::ArtifactRecord& preview = artifacts["pairs/cloud.preview.ply"];
  EXPECT_GT(full.size, 20'000'000);
  EXPECT_LE(preview.size, 20'000'000);
  EXPECT_GT(preview.size, 19'000'000);
  EXPECT_EQ(preview.sha256.size(), 64u);
  EXPECT_TRUE(std::filesystem::exists(data_dir_.root() / preview.path));
  for (const auto& [name, artifact] : artifacts) {
    EXPECT_EQ(name.find(".part-"), std::string::npos) << name;
  }
}

TEST_F(WorkerPoolTest, WorkersRunAtNormalPriorityByDefault) {
  StartPool();
  const std::string id = Submit();
  SetGate(true);
  WaitForChange("succeeded 1.000000");
  const json result = json::parse(*store_.GetResult(id));
  EXPECT_EQ(result["nice"], 0);
  EXPECT_EQ(result["sched_other"], true);
}

TEST_F(WorkerPoolTest, NiceAndIdleSchedulingWhenAsked) {
  WorkerPoolOptions options;
  options.nice = 5;
  options.idle_scheduling = true;
  StartPool(options);
  const std::string id = Submit();
  SetGate(true);
  WaitForChange("succeeded 1.000000");
  const json result = json::parse(*store_.GetResult(id));
  EXPECT_EQ(result["nice"], 5);
  EXPECT_EQ(result["sched_other"], false);  // SCHED_IDLE
}

TEST_F(WorkerPoolTest, CancelStopsARunningJob) {
  WorkerPool& pool = StartPool();
  const std::string id = Submit();
  WaitForChange("running 0.500000");
  EXPECT_FALSE(pool.Cancel("no-such-job"));
  EXPECT_TRUE(pool.Cancel(id));
  WaitForChange("canceled 0.500000");
  EXPECT_EQ(Job(id).state, storage::JobState::kCanceled);
}

TEST_F(WorkerPoolTest, DrainHandsARunningJobBackToTheQueue) {
  WorkerPool& pool = StartPool();
  const std::string id = Submit();
  WaitForChange("running 0.500000");
  EXPECT_EQ(pool.Drain(0), 1);
  const storage::JobRecord job = Job(id);
  EXPECT_EQ(job.state, storage::JobState::kQueued);
  // A new pool runs it to the end; the interrupted attempt does not count.
  SetGate(true);
  StartPool();
  pool_->Notify();
  WaitForChange("succeeded 1.000000");
  EXPECT_EQ(Job(id).attempts, 1);
}

}  // namespace
}  // namespace omnirig::server
