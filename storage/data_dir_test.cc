#include "storage/data_dir.h"

#include <gtest/gtest.h>

#include "storage/atomic_file.h"
#include "storage/sqlite_job_store.h"
#include "testing/storage/test_util.h"

namespace omnirig::storage {
namespace {

TEST(DataDir, ConsistencyCheckRepairsFilesAgainstRecords) {
  testing::TempDir dir;
  DataDir data(dir.path());
  SqliteJobStore store(data.DatabasePath().string());
  const std::string dataset = store.CreateDataset("d").id;
  const FileDigest kept = WriteFileAtomically(data.ImagesDir(dataset) / "cam0/a.png", "abcd");
  store.PutImage(dataset, ImageRecord{"cam0/a.png", kept.size, kept.sha256, 1, 1, "image/png"});
  store.PutImage(dataset, ImageRecord{"cam0/gone.png", 3, "x", 1, 1, "image/png"});
  WriteFileAtomically(data.ImagesDir(dataset) / ".b.png.part-123456789abc", "torn");
  std::filesystem::create_directories(data.DatasetDir("deleted"));
  std::filesystem::create_directories(data.JobDir("deleted-job"));

  const ConsistencyReport report = CheckConsistency(data, store);
  EXPECT_EQ(report.integrity, "ok");
  EXPECT_TRUE(report.ok());
  EXPECT_EQ(report.temporary_files_removed, 1);
  EXPECT_EQ(report.missing_images, std::vector<std::string>{dataset + "/cam0/gone.png"});
  EXPECT_EQ(report.orphan_folders_removed, 2);
  ASSERT_EQ(store.ListImages(dataset).size(), 1u);
  EXPECT_EQ(store.ListImages(dataset)[0].name, "cam0/a.png");
}

TEST(DataDir, ReportsMissingArtifacts) {
  testing::TempDir dir;
  DataDir data(dir.path());
  SqliteJobStore store(data.DatabasePath().string());
  const auto job = store.CreateJob("t", "d", "{}");
  const auto claimed = store.ClaimNextJob({});
  ASSERT_TRUE(claimed);
  JobOutcome outcome;
  outcome.result = "{}";
  outcome.artifacts.push_back(
      ArtifactRecord{"out.bin", "jobs/" + job.id + "/attempt-1/out.bin", 3, "x", "a/b"});
  ASSERT_TRUE(store.FinishJob(job.id, claimed->lease_token, outcome));
  std::filesystem::create_directories(data.AttemptDir(job.id, 1));
  const ConsistencyReport report = CheckConsistency(data, store);
  EXPECT_FALSE(report.ok());
  EXPECT_EQ(report.missing_artifacts, std::vector<std::string>{job.id + "/out.bin"});
  EXPECT_GT(data.FreeBytes(), 0);
}

}  // namespace
}  // namespace omnirig::storage
