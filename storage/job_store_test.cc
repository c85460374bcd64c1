// The JobStore contract (job_store.h), one typed suite run against SQLite and against a real
// PostgreSQL 15 started for this test (postgres_test_server.h). Each test gets a fresh store:
// a new SQLite file, or a new PostgreSQL database; Open() called twice opens two handles on the
// same store, standing for two processes.

#include "storage/job_store.h"

#include <gtest/gtest.h>
#include <libpq-fe.h>

#include <atomic>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <set>
#include <thread>

#include "storage/postgres_job_store.h"
#include "storage/sqlite_job_store.h"
#include "storage/store_copy.h"
#include "testing/storage/postgres_test_server.h"
#include "testing/storage/test_util.h"

namespace omnirig::storage {
namespace {

struct SqliteBackend {
  std::unique_ptr<JobStore> Open() {
    return std::make_unique<SqliteJobStore>((dir.path() / "omnirig.db").string());
  }
  testing::TempDir dir;
};

struct PostgresBackend {
  std::unique_ptr<JobStore> Open() { return std::make_unique<PostgresJobStore>(url); }
  std::string url = testing::SharedPostgresTestServer().CreateDatabase();
};

template <typename Backend>
class JobStoreContractTest : public ::testing::Test {
 protected:
  std::unique_ptr<JobStore> Open() { return backend_.Open(); }
  Backend backend_;
};

class BackendNames {
 public:
  template <typename T>
  static std::string GetName(int) {
    return std::is_same_v<T, SqliteBackend> ? "Sqlite" : "Postgres";
  }
};

using Backends = ::testing::Types<SqliteBackend, PostgresBackend>;
TYPED_TEST_SUITE(JobStoreContractTest, Backends, BackendNames);

TYPED_TEST(JobStoreContractTest, ImagesAreIdempotentAndCounted) {
  auto owned = this->Open();
  JobStore& store = *owned;
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

TYPED_TEST(JobStoreContractTest, PutImagesStoresABatchLikePutImageInOrder) {
  auto owned = this->Open();
  JobStore& store = *owned;
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

TYPED_TEST(JobStoreContractTest, ReadersSeeAnImageBatchWholeOrNotAtAll) {
  auto owned = this->Open();
  JobStore& store = *owned;
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

TYPED_TEST(JobStoreContractTest, JobLifecycle) {
  auto owned = this->Open();
  JobStore& store = *owned;
  const JobRecord created = store.CreateJob("calibration", "ds", R"({"a":1})");
  EXPECT_EQ(created.state, JobState::kQueued);
  auto claimed = store.ClaimNextJob({});
  ASSERT_TRUE(claimed);
  EXPECT_EQ(claimed->id, created.id);
  EXPECT_EQ(claimed->state, JobState::kRunning);
  EXPECT_EQ(claimed->attempts, 1);
  EXPECT_FALSE(store.ClaimNextJob({}));
  store.UpdateProgress(created.id, JobProgress{0.5, "solve", "iteration 3", 2.0});
  EXPECT_DOUBLE_EQ(store.GetJob(created.id)->progress.fraction, 0.5);
  EXPECT_FALSE(store.GetResult(created.id));
  JobOutcome outcome;
  outcome.result = R"({"ok":true})";
  outcome.artifacts.push_back(
      ArtifactRecord{"result.json", "jobs/x/result.json", 11, "ff", "application/json"});
  EXPECT_TRUE(store.FinishJob(created.id, claimed->lease_token, outcome));
  // No longer running.
  EXPECT_FALSE(store.FinishJob(created.id, claimed->lease_token, outcome));
  const auto finished = store.GetJob(created.id);
  EXPECT_EQ(finished->state, JobState::kSucceeded);
  EXPECT_DOUBLE_EQ(finished->progress.fraction, 1.0);
  EXPECT_EQ(*store.GetResult(created.id), R"({"ok":true})");
  EXPECT_EQ(store.ListArtifacts(created.id).size(), 1u);
  EXPECT_FALSE(store.RetryJob(created.id));  // succeeded jobs are not retried
  EXPECT_TRUE(store.DeleteJob(created.id));
  EXPECT_FALSE(store.GetJob(created.id));
}

TYPED_TEST(JobStoreContractTest, CancelQueuedAndRunning) {
  auto owned = this->Open();
  JobStore& store = *owned;
  const auto first = store.CreateJob("t", "ds", "{}");
  const auto second = store.CreateJob("t", "ds", "{}");
  ASSERT_EQ(store.ClaimNextJob({})->id, first.id);  // oldest first
  EXPECT_EQ(store.RequestCancel(second.id), JobState::kCanceled);
  EXPECT_EQ(store.RequestCancel(first.id), JobState::kRunning);
  EXPECT_TRUE(store.GetJob(first.id)->cancel_requested);
  EXPECT_FALSE(store.RequestCancel("missing"));
  EXPECT_FALSE(store.DeleteJob(first.id));  // running
  EXPECT_TRUE(store.RetryJob(second.id));
  EXPECT_EQ(store.GetJob(second.id)->state, JobState::kQueued);
}

TYPED_TEST(JobStoreContractTest, RecoveryRequeuesThenFails) {
  auto owned = this->Open();
  JobStore& store = *owned;
  const auto job = store.CreateJob("t", "ds", "{}");
  const auto canceled = store.CreateJob("t", "ds", "{}");
  for (int attempt = 1; attempt <= 3; ++attempt) {
    std::set<std::string> running;
    while (auto claimed = store.ClaimNextJob({})) running.insert(claimed->id);
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

TYPED_TEST(JobStoreContractTest, ConcurrentClaimsNeverShareAJob) {
  auto owned = this->Open();
  JobStore& store = *owned;
  for (int i = 0; i < 40; ++i) store.CreateJob("t", "ds", "{}");
  std::mutex mutex;
  std::vector<std::string> claimed;
  std::vector<std::thread> workers;
  for (int w = 0; w < 4; ++w) {
    workers.emplace_back([&] {
      while (auto job = store.ClaimNextJob({})) {
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

TYPED_TEST(JobStoreContractTest, FiltersJobs) {
  auto owned = this->Open();
  JobStore& store = *owned;
  store.CreateJob("a", "d1", "{}");
  store.CreateJob("b", "d2", "{}");
  JobFilter by_type;
  by_type.type = "b";
  ASSERT_EQ(store.ListJobs(by_type).size(), 1u);
  JobFilter by_state;
  by_state.state = JobState::kRunning;
  EXPECT_TRUE(store.ListJobs(by_state).empty());
  EXPECT_EQ(store.ListJobs(JobFilter{}).size(), 2u);
  JobFilter unlimited;
  unlimited.limit = -1;
  EXPECT_EQ(store.ListJobs(unlimited).size(), 2u);
  EXPECT_EQ(store.CountActiveJobs("d1"), 1);
}

// Two stores on one database stand for two server processes sharing the queue: a cancel written by
// one is seen by the other's next read (its cached statements must not keep an old snapshot).
TYPED_TEST(JobStoreContractTest, SecondStoreSeesCancelAndProgressOfTheFirst) {
  auto worker_owned = this->Open();
  auto api_owned = this->Open();
  JobStore& worker_side = *worker_owned;
  JobStore& api_side = *api_owned;
  const std::string dataset = worker_side.CreateDataset("rig").id;
  const JobRecord job = api_side.CreateJob("calibration", dataset, "{}");
  const auto claimed = worker_side.ClaimNextJob({});
  ASSERT_TRUE(claimed);
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
  EXPECT_TRUE(worker_side.FinishJob(job.id, claimed->lease_token, outcome));
  EXPECT_EQ(api_side.GetJob(job.id)->state, JobState::kCanceled);
}

TYPED_TEST(JobStoreContractTest, ClaimLeasesTheJobToTheWorker) {
  auto owned = this->Open();
  JobStore& store = *owned;
  const JobRecord job = store.CreateJob("t", "ds", "{}");
  EXPECT_TRUE(job.worker_id.empty());
  const double before = NowSeconds();
  const auto claimed = store.ClaimNextJob(ClaimRequest{"host-a:12", 30});
  ASSERT_TRUE(claimed);
  EXPECT_EQ(claimed->worker_id, "host-a:12");
  EXPECT_FALSE(claimed->lease_token.empty());
  ASSERT_TRUE(claimed->lease_expires_at);
  // The database's clock may be another machine's: allow a second of skew, not the lease.
  EXPECT_GT(*claimed->lease_expires_at, before + 29);
  EXPECT_LT(*claimed->lease_expires_at, NowSeconds() + 31);
  EXPECT_EQ(store.GetJob(job.id)->worker_id, "host-a:12");
  EXPECT_EQ(store.GetJob(job.id)->lease_token, claimed->lease_token);
}

TYPED_TEST(JobStoreContractTest, RenewLeaseNeedsTheCurrentToken) {
  auto owned = this->Open();
  JobStore& store = *owned;
  const JobRecord job = store.CreateJob("t", "ds", "{}");
  const auto claimed = store.ClaimNextJob(ClaimRequest{"w", 10});
  ASSERT_TRUE(claimed);
  EXPECT_TRUE(store.RenewLease(job.id, claimed->lease_token, 100));
  EXPECT_GT(*store.GetJob(job.id)->lease_expires_at, *claimed->lease_expires_at + 50);
  EXPECT_FALSE(store.RenewLease(job.id, "not-the-token", 100));
  EXPECT_FALSE(store.RenewLease("missing", claimed->lease_token, 100));
  JobOutcome outcome;
  outcome.result = "{}";
  ASSERT_TRUE(store.FinishJob(job.id, claimed->lease_token, outcome));
  EXPECT_FALSE(store.RenewLease(job.id, claimed->lease_token, 100));  // no longer running
}

// A worker stopped past its lease (SIGSTOP, a network cut): the job goes to another worker, and
// the first worker's late end is refused, whatever it says.
TYPED_TEST(JobStoreContractTest, ExpiredLeaseIsRequeuedAndTheLateFinishRefused) {
  auto owned = this->Open();
  JobStore& store = *owned;
  const JobRecord job = store.CreateJob("t", "ds", "{}");
  const JobRecord healthy = store.CreateJob("t", "ds", "{}");
  const auto stale = store.ClaimNextJob(ClaimRequest{"stopped", 0});  // expires at once
  const auto alive = store.ClaimNextJob(ClaimRequest{"alive", 3600});
  ASSERT_TRUE(stale && alive);
  ASSERT_EQ(stale->id, job.id);
  const RecoveryReport report = store.RecoverExpiredLeases(3);
  EXPECT_EQ(report.requeued, std::vector<std::string>{job.id});
  EXPECT_TRUE(report.failed.empty() && report.canceled.empty());
  EXPECT_EQ(store.GetJob(healthy.id)->state, JobState::kRunning);  // its lease holds
  EXPECT_EQ(store.GetJob(job.id)->state, JobState::kQueued);
  EXPECT_EQ(store.GetJob(job.id)->attempts, 1);  // the lost run counts

  const auto takeover = store.ClaimNextJob(ClaimRequest{"other", 3600});
  ASSERT_TRUE(takeover);
  EXPECT_EQ(takeover->id, job.id);
  EXPECT_EQ(takeover->attempts, 2);
  EXPECT_NE(takeover->lease_token, stale->lease_token);

  JobOutcome late;
  late.state = JobState::kFailed;
  late.error = JobError{"job_failed", "the stale run"};
  EXPECT_FALSE(store.FinishJob(job.id, stale->lease_token, late));
  EXPECT_FALSE(store.RequeueJob(job.id, stale->lease_token));
  EXPECT_FALSE(store.RenewLease(job.id, stale->lease_token, 60));
  EXPECT_EQ(store.GetJob(job.id)->state, JobState::kRunning);
  JobOutcome good;
  good.result = R"({"run":2})";
  good.artifacts.push_back(ArtifactRecord{"r.json", "jobs/r.json", 2, "ab", "application/json"});
  EXPECT_TRUE(store.FinishJob(job.id, takeover->lease_token, good));
  EXPECT_FALSE(store.FinishJob(job.id, stale->lease_token, late));  // still refused after
  EXPECT_EQ(store.GetJob(job.id)->state, JobState::kSucceeded);
  EXPECT_EQ(store.GetJob(job.id)->worker_id, "other");
  EXPECT_EQ(*store.GetResult(job.id), R"({"run":2})");
  EXPECT_EQ(store.ListArtifacts(job.id).size(), 1u);
}

TYPED_TEST(JobStoreContractTest, ExpiredLeasesFailAfterMaxAttemptsAndHonourCancel) {
  auto owned = this->Open();
  JobStore& store = *owned;
  const JobRecord job = store.CreateJob("t", "ds", "{}");
  const JobRecord canceled = store.CreateJob("t", "ds", "{}");
  for (int attempt = 1; attempt <= 2; ++attempt) {
    std::set<std::string> claimed;
    while (auto next = store.ClaimNextJob(ClaimRequest{"w", 0})) claimed.insert(next->id);
    if (attempt == 1) {
      EXPECT_EQ(claimed.size(), 2u);
      EXPECT_EQ(store.RequestCancel(canceled.id), JobState::kRunning);
    }
    const RecoveryReport report = store.RecoverExpiredLeases(2);
    if (attempt == 1) {
      EXPECT_EQ(report.canceled, std::vector<std::string>{canceled.id});
      EXPECT_EQ(report.requeued, std::vector<std::string>{job.id});
    } else {
      EXPECT_EQ(report.failed, std::vector<std::string>{job.id});
    }
  }
  const auto failed = store.GetJob(job.id);
  EXPECT_EQ(failed->state, JobState::kFailed);
  EXPECT_EQ(failed->attempts, 2);
  ASSERT_TRUE(failed->error);
  EXPECT_EQ(failed->error->code, "interrupted");
  EXPECT_EQ(store.GetJob(canceled.id)->state, JobState::kCanceled);
  EXPECT_TRUE(store.RecoverExpiredLeases(2).requeued.empty());
}

TYPED_TEST(JobStoreContractTest, RequeueNeedsTheLeaseAndDoesNotCountTheAttempt) {
  auto owned = this->Open();
  JobStore& store = *owned;
  const JobRecord job = store.CreateJob("t", "ds", "{}");
  const auto claimed = store.ClaimNextJob({});
  ASSERT_TRUE(claimed);
  EXPECT_FALSE(store.RequeueJob(job.id, "not-the-token"));
  EXPECT_TRUE(store.RequeueJob(job.id, claimed->lease_token));
  EXPECT_EQ(store.GetJob(job.id)->state, JobState::kQueued);
  EXPECT_EQ(store.GetJob(job.id)->attempts, 0);
  EXPECT_EQ(store.ClaimNextJob({})->attempts, 1);
}

TYPED_TEST(JobStoreContractTest, HeartbeatsListLiveWorkersAndTheirJobs) {
  auto owned = this->Open();
  JobStore& store = *owned;
  EXPECT_TRUE(store.ListWorkers(60).empty());
  const double started = NowSeconds();
  store.RecordHeartbeat(WorkerRecord{"b:2", started, 0, {}});
  store.RecordHeartbeat(WorkerRecord{"a:1", started, 0, {"j1", "j2"}});
  store.RecordHeartbeat(WorkerRecord{"a:1", started, 0, {"j3"}});  // the latest wins
  const auto workers = store.ListWorkers(60);
  ASSERT_EQ(workers.size(), 2u);
  EXPECT_EQ(workers[0].id, "a:1");
  EXPECT_EQ(workers[0].running_jobs, std::vector<std::string>{"j3"});
  EXPECT_DOUBLE_EQ(workers[0].started_at, started);
  EXPECT_GE(workers[0].last_seen_at, started);
  EXPECT_TRUE(workers[1].running_jobs.empty());
  EXPECT_TRUE(store.ListWorkers(-60).empty());  // none seen in the future
}

// PostgreSQL wakes a waiting worker when another process queues a job; SQLite (one process)
// leaves the waking to the worker pool.
TYPED_TEST(JobStoreContractTest, QueueChangesWakeOtherProcesses) {
  auto api_owned = this->Open();
  auto worker_owned = this->Open();
  if (!worker_owned->NotifiesQueueChanges()) {
    EXPECT_FALSE(worker_owned->WaitForQueueChange(0));
    return;
  }
  // The first wait subscribes (and reports a possible change); later ones wait for NOTIFY.
  EXPECT_TRUE(worker_owned->WaitForQueueChange(0));
  while (worker_owned->WaitForQueueChange(0)) {
  }
  std::thread producer([&] { api_owned->CreateJob("t", "ds", "{}"); });
  EXPECT_TRUE(worker_owned->WaitForQueueChange(30));
  producer.join();
  EXPECT_TRUE(worker_owned->ClaimNextJob({}));
  EXPECT_FALSE(worker_owned->WaitForQueueChange(0));
}

// The schema version recorded in the database at `url`.
int StoredSchemaVersion(const std::string& url) {
  PGconn* db = PQconnectdb(url.c_str());
  PGresult* rows = PQexec(db, "SELECT version FROM omnirig_schema");
  const int version = PQntuples(rows) == 0 ? 0 : std::atoi(PQgetvalue(rows, 0, 0));
  PQclear(rows);
  PQfinish(db);
  return version;
}

TEST(PostgresJobStoreTest, MigratesOnceAndRefusesANewerSchema) {
  const std::string url = testing::SharedPostgresTestServer().CreateDatabase();
  std::string dataset_id;
  {
    PostgresJobStore store(url);
    dataset_id = store.CreateDataset("rig").id;
    EXPECT_EQ(StoredSchemaVersion(url), PostgresJobStore::SchemaVersion());
  }
  EXPECT_EQ(PostgresJobStore::SchemaVersion(), SqliteJobStore::SchemaVersion());
  {
    // Several processes starting at once migrate under one lock.
    std::vector<std::thread> openers;
    const std::string fresh = testing::SharedPostgresTestServer().CreateDatabase();
    std::atomic<int> opened{0};
    for (int i = 0; i < 4; ++i) {
      openers.emplace_back([&] {
        PostgresJobStore store(fresh, 1);
        opened += StoredSchemaVersion(fresh) == PostgresJobStore::SchemaVersion();
      });
    }
    for (auto& opener : openers) opener.join();
    EXPECT_EQ(opened, 4);
  }
  PostgresJobStore reopened(url);
  ASSERT_TRUE(reopened.GetDataset(dataset_id));
  EXPECT_EQ(reopened.IntegrityCheck(), "ok");
  // A newer build's database: refused rather than written with an older schema.
  {
    PGconn* db = PQconnectdb(url.c_str());
    PQclear(PQexec(db, ("UPDATE omnirig_schema SET version = " +
                        std::to_string(PostgresJobStore::SchemaVersion() + 1))
                           .c_str()));
    PQfinish(db);
  }
  EXPECT_THROW(PostgresJobStore newer(url), PostgresError);
}

void ExpectSameJob(const JobRecord& a, const JobRecord& b) {
  EXPECT_EQ(a.id, b.id);
  EXPECT_EQ(a.type, b.type);
  EXPECT_EQ(a.dataset_id, b.dataset_id);
  EXPECT_EQ(a.params, b.params);
  EXPECT_EQ(a.state, b.state);
  EXPECT_DOUBLE_EQ(a.progress.fraction, b.progress.fraction);
  EXPECT_EQ(a.progress.stage, b.progress.stage);
  EXPECT_EQ(a.progress.message, b.progress.message);
  EXPECT_EQ(a.progress.eta_s, b.progress.eta_s);
  EXPECT_DOUBLE_EQ(a.created_at, b.created_at);
  EXPECT_EQ(a.started_at, b.started_at);
  EXPECT_EQ(a.finished_at, b.finished_at);
  EXPECT_EQ(a.attempts, b.attempts);
  EXPECT_EQ(a.error.has_value(), b.error.has_value());
  if (a.error && b.error) {
    EXPECT_EQ(a.error->code, b.error->code);
    EXPECT_EQ(a.error->message, b.error->message);
  }
  EXPECT_EQ(a.cancel_requested, b.cancel_requested);
  EXPECT_EQ(a.worker_id, b.worker_id);
  EXPECT_EQ(a.lease_token, b.lease_token);
}

// Imports (store copy) keep a record as given and leave an existing id alone (false).
TYPED_TEST(JobStoreContractTest, ImportsKeepRecordsAndSkipExistingIds) {
  auto owned = this->Open();
  JobStore& store = *owned;
  const DatasetRecord dataset = store.CreateDataset("d");
  EXPECT_FALSE(store.ImportDataset(DatasetRecord{dataset.id, "other", 1.0}));
  EXPECT_EQ(store.GetDataset(dataset.id)->name, "d");
  ASSERT_TRUE(store.ImportDataset(DatasetRecord{"copied", "c", 12.5}));
  EXPECT_DOUBLE_EQ(store.GetDataset("copied")->created_at, 12.5);

  JobRecord job;
  job.id = "done";
  job.type = "calibration";
  job.dataset_id = "copied";
  job.params = "{}";
  job.state = JobState::kFailed;
  job.created_at = 20;
  job.attempts = 2;
  job.error = JobError{"job_failed", "no board"};
  const ArtifactRecord log{"log.txt", "jobs/done/attempt-2/log.txt", 3, "ab", "text/plain"};
  ASSERT_TRUE(store.ImportJob(job, std::nullopt, {log}));
  ExpectSameJob(*store.GetJob("done"), job);
  ASSERT_EQ(store.ListArtifacts("done").size(), 1u);
  EXPECT_EQ(store.ListArtifacts("done")[0].path, log.path);
  job.state = JobState::kQueued;
  EXPECT_FALSE(store.ImportJob(job, std::nullopt, {}));
  EXPECT_EQ(store.GetJob("done")->state, JobState::kFailed);
  EXPECT_EQ(store.ListArtifacts("done").size(), 1u);
}

// A one-machine service's records moved to PostgreSQL: every dataset, image, job (each state),
// result and artifact record arrives unchanged; a second copy adds nothing; the queue and
// recovery carry on from there.
TEST(StoreCopyTest, SqliteToPostgresKeepsEveryRecord) {
  testing::TempDir dir;
  SqliteJobStore from((dir.path() / "omnirig.db").string());
  const DatasetRecord dataset = from.CreateDataset("rig");
  from.PutImages(dataset.id, {ImageRecord{"cam0/a.png", 10, "aa", 4, 3, "image/png"},
                              ImageRecord{"cam1/b.png", 12, "bb", 5, 6, "image/png"}});
  from.CreateDataset("empty");
  const JobRecord succeeded = from.CreateJob("calibration", dataset.id, R"({"a":1})");
  const JobRecord failed = from.CreateJob("calibration", dataset.id, "{}");
  const JobRecord canceled = from.CreateJob("calibration", dataset.id, "{}");
  const JobRecord running = from.CreateJob("calibration", dataset.id, "{}");
  const JobRecord queued = from.CreateJob("calibration", dataset.id, R"({"q":2})");
  JobOutcome ok;
  ok.result = R"({"rms_px":0.1})";
  ok.artifacts = {
      ArtifactRecord{"log.txt", "jobs/x/attempt-1/log.txt", 5, "cc", "text/plain"},
      ArtifactRecord{"result.json", "jobs/x/attempt-1/result.json", 9, "dd", "application/json"}};
  auto claim = from.ClaimNextJob(ClaimRequest{"box:1", 60});
  from.UpdateProgress(claim->id, JobProgress{0.5, "solve", "half", 2.0});
  ASSERT_TRUE(from.FinishJob(claim->id, claim->lease_token, ok));
  claim = from.ClaimNextJob(ClaimRequest{"box:1", 60});
  JobOutcome bad;
  bad.state = JobState::kFailed;
  bad.error = JobError{"invalid_input", "no board"};
  ASSERT_TRUE(from.FinishJob(claim->id, claim->lease_token, bad));
  from.RequestCancel(canceled.id);
  ASSERT_EQ(from.ClaimNextJob(ClaimRequest{"box:1", 60})->id, running.id);

  PostgresJobStore to(testing::SharedPostgresTestServer().CreateDatabase());
  const StoreCopyReport report = CopyStore(from, to);
  EXPECT_EQ(report.datasets, 2);
  EXPECT_EQ(report.images, 2);
  EXPECT_EQ(report.jobs, 5);
  EXPECT_EQ(report.artifacts, 2);
  ASSERT_EQ(to.ListDatasets().size(), 2u);
  EXPECT_EQ(to.GetDataset(dataset.id)->name, "rig");
  EXPECT_DOUBLE_EQ(to.GetDataset(dataset.id)->created_at, dataset.created_at);
  EXPECT_EQ(to.GetDataset(dataset.id)->total_bytes, 22);
  ASSERT_EQ(to.ListImages(dataset.id).size(), 2u);
  EXPECT_EQ(to.ListImages(dataset.id)[1].sha256, "bb");
  EXPECT_EQ(to.ListImages(dataset.id)[1].height, 6);
  for (const JobRecord& job : from.ListJobs(JobFilter{})) {
    SCOPED_TRACE(job.id);
    ASSERT_TRUE(to.GetJob(job.id));
    ExpectSameJob(*to.GetJob(job.id), job);
    EXPECT_EQ(to.GetResult(job.id), from.GetResult(job.id));
    const auto artifacts = to.ListArtifacts(job.id);
    const auto expected = from.ListArtifacts(job.id);
    ASSERT_EQ(artifacts.size(), expected.size());
    for (size_t i = 0; i < artifacts.size(); ++i) {
      EXPECT_EQ(artifacts[i].path, expected[i].path);
      EXPECT_EQ(artifacts[i].sha256, expected[i].sha256);
      EXPECT_EQ(artifacts[i].size, expected[i].size);
    }
  }
  EXPECT_EQ(to.GetJob(succeeded.id)->state, JobState::kSucceeded);
  EXPECT_EQ(to.GetJob(failed.id)->error->code, "invalid_input");

  const StoreCopyReport again = CopyStore(from, to);
  EXPECT_EQ(again.jobs + again.datasets, 0);
  EXPECT_EQ(again.jobs_skipped, 5);
  EXPECT_EQ(again.datasets_skipped, 2);

  // The copied running job (its server stopped) counts as interrupted; the queued one is next.
  EXPECT_EQ(to.RecoverExpiredLeases(3).requeued, std::vector<std::string>{running.id});
  const auto next = to.ClaimNextJob(ClaimRequest{"pg:1", 60});
  ASSERT_TRUE(next);
  EXPECT_EQ(next->id, running.id);  // queued earlier than `queued`
  EXPECT_EQ(next->attempts, 2);
  EXPECT_EQ(to.ClaimNextJob(ClaimRequest{"pg:1", 60})->id, queued.id);
}

TEST(PostgresJobStoreTest, UnreachableServerIsAClearError) {
  try {
    PostgresJobStore store("postgresql://postgres@127.0.0.1:1/none");
    FAIL() << "connected to nothing";
  } catch (const StoreUnavailable& e) {
    EXPECT_NE(std::string(e.what()).find("cannot connect to PostgreSQL"), std::string::npos);
  }
}

}  // namespace
}  // namespace omnirig::storage
