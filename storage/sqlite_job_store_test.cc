#include "storage/sqlite_job_store.h"

#include <gtest/gtest.h>

#include <atomic>
#include <set>
#include <thread>

#include "storage/test_util.h"

namespace omnirig::storage {
namespace {

class SqliteJobStoreTest : public ::testing::Test {
 protected:
  std::string DbPath() const { return (dir_.path() / "omnirig.db").string(); }
  testing::TempDir dir_;
};

TEST_F(SqliteJobStoreTest, MigratesAndReopens) {
  std::string dataset_id;
  {
    SqliteJobStore store(DbPath());
    dataset_id = store.CreateDataset("rig").id;
  }
  SqliteJobStore reopened(DbPath());
  ASSERT_TRUE(reopened.GetDataset(dataset_id));
  EXPECT_EQ(reopened.GetDataset(dataset_id)->name, "rig");
  EXPECT_EQ(reopened.IntegrityCheck(), "ok");
  Connection raw(DbPath());
  Statement version(raw.handle(), "PRAGMA user_version");
  ASSERT_TRUE(version.Step());
  EXPECT_EQ(version.Int(0), SqliteJobStore::SchemaVersion());
  Statement mode(raw.handle(), "PRAGMA journal_mode");
  ASSERT_TRUE(mode.Step());
  EXPECT_EQ(mode.Text(0), "wal");
}

TEST_F(SqliteJobStoreTest, RefusesDatabaseFromNewerBuild) {
  { SqliteJobStore store(DbPath()); }
  {
    Connection raw(DbPath());
    raw.Exec("PRAGMA user_version = " + std::to_string(SqliteJobStore::SchemaVersion() + 1));
  }
  EXPECT_THROW(SqliteJobStore store(DbPath()), SqliteError);
}

TEST_F(SqliteJobStoreTest, ImagesAreIdempotentAndCounted) {
  SqliteJobStore store(DbPath());
  const std::string id = store.CreateDataset("d").id;
  store.PutImage(id, ImageRecord{"cam0/1.png", 10, "aa", 4, 3, "image/png"});
  store.PutImage(id, ImageRecord{"cam0/1.png", 12, "bb", 4, 3, "image/png"});
  store.PutImage(id, ImageRecord{"cam1/1.png", 5, "cc", 4, 3, "image/png"});
  const auto images = store.ListImages(id);
  ASSERT_EQ(images.size(), 2u);
  EXPECT_EQ(images[0].sha256, "bb");
  const auto dataset = store.GetDataset(id);
  EXPECT_EQ(dataset->image_count, 2);
  EXPECT_EQ(dataset->total_bytes, 17);
  EXPECT_TRUE(store.DeleteDataset(id));
  EXPECT_FALSE(store.GetDataset(id));
  EXPECT_TRUE(store.ListImages(id).empty());
}

TEST_F(SqliteJobStoreTest, PutImagesStoresABatchLikePutImageInOrder) {
  SqliteJobStore store(DbPath());
  const std::string id = store.CreateDataset("d").id;
  store.PutImage(id, ImageRecord{"cam0/0.png", 7, "00", 4, 3, "image/png"});
  store.PutImages(id, {ImageRecord{"cam0/1.png", 10, "aa", 4, 3, "image/png"},
                       ImageRecord{"cam0/0.png", 5, "cc", 4, 3, "image/png"},
                       ImageRecord{"cam0/1.png", 12, "bb", 4, 3, "image/png"}});
  const auto images = store.ListImages(id);
  ASSERT_EQ(images.size(), 2u);
  EXPECT_EQ(images[0].sha256, "cc");  // replaced the earlier upload
  EXPECT_EQ(images[1].sha256, "bb");  // the later record of a name wins
  EXPECT_EQ(store.GetDataset(id)->image_count, 2);
  EXPECT_EQ(store.GetDataset(id)->total_bytes, 17);
  store.PutImages(id, {});  // an empty batch is a no-op
  EXPECT_EQ(store.ListImages(id).size(), 2u);
  // A batch that fails (here: no such dataset) stores nothing.
  EXPECT_THROW(store.PutImages("missing", {ImageRecord{"x.png", 1, "dd", 1, 1, "image/png"}}),
               std::exception);
  EXPECT_TRUE(store.ListImages("missing").empty());
}

TEST_F(SqliteJobStoreTest, ReadersSeeAnImageBatchWholeOrNotAtAll) {
  SqliteJobStore store(DbPath());
  const std::string id = store.CreateDataset("d").id;
  constexpr int kImages = 2000;
  std::vector<ImageRecord> batch;
  for (int i = 0; i < kImages; ++i) {
    batch.push_back(
        ImageRecord{"cam0/" + std::to_string(i) + ".png", 100, "ab", 4, 3, "image/png"});
  }
  // A reader polls the dataset's image count while the batch is written: one commit per record
  // would show it counts in between.
  std::atomic<bool> written{false};
  std::set<int64_t> seen;
  std::thread reader([&] {
    while (true) {
      const bool last = written;  // read once more after the batch is in
      seen.insert(store.GetDataset(id)->image_count);
      if (last) return;
    }
  });
  store.PutImages(id, batch);
  written = true;
  reader.join();
  for (const int64_t count : seen) EXPECT_TRUE(count == 0 || count == kImages) << count;
  EXPECT_EQ(seen.count(kImages), 1u);
  EXPECT_EQ(store.GetDataset(id)->total_bytes, 100 * kImages);
}

TEST_F(SqliteJobStoreTest, JobLifecycle) {
  SqliteJobStore store(DbPath());
  const JobRecord created = store.CreateJob("calibration", "ds", R"({"a":1})");
  EXPECT_EQ(created.state, JobState::kQueued);
  auto claimed = store.ClaimNextJob();
  ASSERT_TRUE(claimed);
  EXPECT_EQ(claimed->id, created.id);
  EXPECT_EQ(claimed->state, JobState::kRunning);
  EXPECT_EQ(claimed->attempts, 1);
  EXPECT_FALSE(store.ClaimNextJob());
  store.UpdateProgress(created.id, JobProgress{0.5, "solve", "iteration 3", 2.0});
  EXPECT_DOUBLE_EQ(store.GetJob(created.id)->progress.fraction, 0.5);
  EXPECT_FALSE(store.GetResult(created.id));
  JobOutcome outcome;
  outcome.result = R"({"ok":true})";
  outcome.artifacts.push_back(
      ArtifactRecord{"result.json", "jobs/x/result.json", 11, "ff", "application/json"});
  EXPECT_TRUE(store.FinishJob(created.id, outcome));
  EXPECT_FALSE(store.FinishJob(created.id, outcome));  // no longer running
  const auto finished = store.GetJob(created.id);
  EXPECT_EQ(finished->state, JobState::kSucceeded);
  EXPECT_DOUBLE_EQ(finished->progress.fraction, 1.0);
  EXPECT_EQ(*store.GetResult(created.id), R"({"ok":true})");
  EXPECT_EQ(store.ListArtifacts(created.id).size(), 1u);
  EXPECT_FALSE(store.RetryJob(created.id));  // succeeded jobs are not retried
  EXPECT_TRUE(store.DeleteJob(created.id));
  EXPECT_FALSE(store.GetJob(created.id));
}

TEST_F(SqliteJobStoreTest, CancelQueuedAndRunning) {
  SqliteJobStore store(DbPath());
  const auto first = store.CreateJob("t", "ds", "{}");
  const auto second = store.CreateJob("t", "ds", "{}");
  ASSERT_EQ(store.ClaimNextJob()->id, first.id);  // oldest first
  EXPECT_EQ(store.RequestCancel(second.id), JobState::kCanceled);
  EXPECT_EQ(store.RequestCancel(first.id), JobState::kRunning);
  EXPECT_TRUE(store.GetJob(first.id)->cancel_requested);
  EXPECT_FALSE(store.RequestCancel("missing"));
  EXPECT_FALSE(store.DeleteJob(first.id));  // running
  EXPECT_TRUE(store.RetryJob(second.id));
  EXPECT_EQ(store.GetJob(second.id)->state, JobState::kQueued);
}

TEST_F(SqliteJobStoreTest, RecoveryRequeuesThenFails) {
  SqliteJobStore store(DbPath());
  const auto job = store.CreateJob("t", "ds", "{}");
  const auto canceled = store.CreateJob("t", "ds", "{}");
  for (int attempt = 1; attempt <= 3; ++attempt) {
    std::set<std::string> running;
    while (auto claimed = store.ClaimNextJob()) running.insert(claimed->id);
    if (attempt == 1) store.RequestCancel(canceled.id);
    const RecoveryReport report = store.RecoverInterruptedJobs(3);
    if (attempt < 3) {
      EXPECT_EQ(report.requeued, std::vector<std::string>{job.id});
      EXPECT_EQ(store.GetJob(job.id)->state, JobState::kQueued);
    } else {
      EXPECT_EQ(report.failed, std::vector<std::string>{job.id});
    }
  }
  const auto failed = store.GetJob(job.id);
  EXPECT_EQ(failed->state, JobState::kFailed);
  EXPECT_EQ(failed->attempts, 3);
  ASSERT_TRUE(failed->error);
  EXPECT_EQ(failed->error->code, "interrupted");
  EXPECT_EQ(store.GetJob(canceled.id)->state, JobState::kCanceled);
}

TEST_F(SqliteJobStoreTest, ConcurrentClaimsNeverShareAJob) {
  SqliteJobStore store(DbPath());
  for (int i = 0; i < 40; ++i) store.CreateJob("t", "ds", "{}");
  std::mutex mutex;
  std::vector<std::string> claimed;
  std::vector<std::thread> workers;
  for (int w = 0; w < 4; ++w) {
    workers.emplace_back([&] {
      while (auto job = store.ClaimNextJob()) {
        std::lock_guard<std::mutex> lock(mutex);
        claimed.push_back(job->id);
      }
    });
  }
  for (auto& worker : workers) worker.join();
  EXPECT_EQ(claimed.size(), 40u);
  EXPECT_EQ(std::set<std::string>(claimed.begin(), claimed.end()).size(), 40u);
  EXPECT_EQ(store.CountJobsByState()[JobState::kRunning], 40);
}

TEST_F(SqliteJobStoreTest, FiltersJobs) {
  SqliteJobStore store(DbPath());
  store.CreateJob("a", "d1", "{}");
  store.CreateJob("b", "d2", "{}");
  JobFilter by_type;
  by_type.type = "b";
  ASSERT_EQ(store.ListJobs(by_type).size(), 1u);
  JobFilter by_state;
  by_state.state = JobState::kRunning;
  EXPECT_TRUE(store.ListJobs(by_state).empty());
  EXPECT_EQ(store.ListJobs(JobFilter{}).size(), 2u);
  EXPECT_EQ(store.CountActiveJobs("d1"), 1);
}

// Two stores on one file stand for two server processes sharing the queue: a cancel written by
// one is seen by the other's next read (its cached statements must not keep an old snapshot).
TEST_F(SqliteJobStoreTest, SecondStoreSeesCancelAndProgressOfTheFirst) {
  SqliteJobStore worker_side(DbPath());
  SqliteJobStore api_side(DbPath());
  const std::string dataset = worker_side.CreateDataset("rig").id;
  const JobRecord job = api_side.CreateJob("calibration", dataset, "{}");
  ASSERT_TRUE(worker_side.ClaimNextJob());
  for (int poll = 0; poll < 3; ++poll) {  // warm both sides' cached statements
    ASSERT_FALSE(worker_side.GetJob(job.id)->cancel_requested);
    ASSERT_EQ(api_side.GetJob(job.id)->state, JobState::kRunning);
  }
  worker_side.UpdateProgress(job.id, JobProgress{0.5, "solve", "half", 3.0});
  EXPECT_DOUBLE_EQ(api_side.GetJob(job.id)->progress.fraction, 0.5);
  EXPECT_EQ(api_side.RequestCancel(job.id), JobState::kRunning);
  EXPECT_TRUE(worker_side.GetJob(job.id)->cancel_requested);
  JobOutcome outcome;
  outcome.state = JobState::kCanceled;
  EXPECT_TRUE(worker_side.FinishJob(job.id, outcome));
  EXPECT_EQ(api_side.GetJob(job.id)->state, JobState::kCanceled);
}

}  // namespace
}  // namespace omnirig::storage
