// The /metrics exposition text: the open-connections gauge reads its source when rendered.

#include "server/metrics.h"

#include <atomic>
#include <string>

#include <gtest/gtest.h>

#include "storage/sqlite_job_store.h"
#include "testing/storage/test_util.h"

namespace omnirig::server {
namespace {

TEST(MetricsTest, OpenConnectionsGaugeReadsItsSourceWhenRendered) {
  storage::testing::TempDir dir;
  storage::SqliteJobStore store((dir.path() / "db.sqlite").string());
  Metrics metrics;
  const std::string kType = "# TYPE omnirig_http_open_connections gauge\n";
  // Without a source the gauge is 0 (the page keeps its shape).
  std::string text = metrics.Render(store, 0, 1);
  EXPECT_NE(text.find(kType + "omnirig_http_open_connections 0\n"), std::string::npos) << text;
  std::atomic<int64_t> open{7};
  metrics.SetOpenConnectionsGauge([&open] { return open.load(); });
  text = metrics.Render(store, 0, 1);
  EXPECT_NE(text.find(kType + "omnirig_http_open_connections 7\n"), std::string::npos) << text;
  open = 123;
  text = metrics.Render(store, 0, 1);
  EXPECT_NE(text.find("\nomnirig_http_open_connections 123\n"), std::string::npos) << text;
  EXPECT_NE(text.find("# HELP omnirig_http_open_connections "), std::string::npos);
}

TEST(MetricsTest, WorkersSeenAliveByHeartbeatWithTheirRunningJobs) {
  storage::testing::TempDir dir;
  storage::SqliteJobStore store((dir.path() / "db.sqlite").string());
  Metrics metrics;
  std::string text = metrics.Render(store, 0, 0);
  EXPECT_NE(text.find("\nomnirig_workers_alive 0\n"), std::string::npos) << text;
  const double now = storage::NowSeconds();
  store.RecordHeartbeat(storage::WorkerRecord{"rig-a:17", now, 0, {"j1", "j2"}});
  store.RecordHeartbeat(storage::WorkerRecord{"rig-b:9", now, 0, {}});
  text = metrics.Render(store, 0, 0);
  EXPECT_NE(text.find("\nomnirig_workers_alive 2\n"), std::string::npos) << text;
  EXPECT_NE(text.find("\nomnirig_worker_running_jobs{worker=\"rig-a:17\"} 2\n"), std::string::npos)
      << text;
  EXPECT_NE(text.find("\nomnirig_worker_running_jobs{worker=\"rig-b:9\"} 0\n"), std::string::npos)
      << text;
  metrics.SetWorkerAliveWindow(-1);  // a heartbeat from the future only: none alive
  EXPECT_NE(metrics.Render(store, 0, 0).find("\nomnirig_workers_alive 0\n"), std::string::npos);
}

}  // namespace
}  // namespace omnirig::server
