#include "storage/sqlite_job_store.h"

#include <gtest/gtest.h>

#include "testing/storage/test_util.h"

namespace omnirig::storage {
namespace {

// SQLite specifics: the file, its pragmas and its user_version. The JobStore contract itself is
// tested against SQLite and PostgreSQL alike in job_store_test.cc.

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
  Statement version(raw, "PRAGMA user_version");
  ASSERT_TRUE(version.Step());
  EXPECT_EQ(version.Int(0), SqliteJobStore::SchemaVersion());
  Statement mode(raw, "PRAGMA journal_mode");
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

}  // namespace
}  // namespace omnirig::storage
