// The data folder on a disk that fills up: a size-limited tmpfs mounted for the test (root, as
// CI runs; skipped with the reason where mounting is impossible). An upload that does not fit
// gets 507 with a JSON error and stores nothing; a job whose outputs fill the disk fails with
// "disk_full" and a message that says so, its outputs removed so that the store can record it;
// the SQLite database passes its integrity check and every recorded file is on disk with its
// sha256; once space returns, uploads and the retried job work with no restart.

#include <gtest/gtest.h>
#include <signal.h>
#include <sqlite3.h>
#include <sys/mount.h>
#include <sys/statvfs.h>
#include <sys/wait.h>

#include <cerrno>
#include <cstring>
#include <fstream>
#include <string>

#include "storage/atomic_file.h"
#include "storage/sha256.h"
#include "tests/server_test_util.h"

namespace omnirig::testing {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

constexpr int64_t kMiB = 1 << 20;

int64_t FreeBytes(const fs::path& path) {
  struct statvfs stats {};
  if (::statvfs(path.c_str(), &stats) != 0) return -1;
  return static_cast<int64_t>(stats.f_bavail) * static_cast<int64_t>(stats.f_frsize);
}

// The rows of `sql` on the database at `path`, each row's columns joined by '|'.
std::vector<std::string> Query(const fs::path& path, const std::string& sql) {
  sqlite3* db = nullptr;
  std::vector<std::string> rows;
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) {
    sqlite3_close(db);
    ADD_FAILURE() << "cannot open " << path;
    return rows;
  }
  sqlite3_stmt* statement = nullptr;
  if (sqlite3_prepare_v2(db, sql.c_str(), -1, &statement, nullptr) != SQLITE_OK) {
    ADD_FAILURE() << sql << ": " << sqlite3_errmsg(db);
  }
  while (statement && sqlite3_step(statement) == SQLITE_ROW) {
    std::string row;
    for (int column = 0; column < sqlite3_column_count(statement); ++column) {
      const auto* text = sqlite3_column_text(statement, column);
      row += (column ? "|" : "") + std::string(text ? reinterpret_cast<const char*>(text) : "");
    }
    rows.push_back(row);
  }
  sqlite3_finalize(statement);
  sqlite3_close(db);
  return rows;
}

std::vector<std::string> Split(const std::string& row) {
  std::vector<std::string> fields;
  size_t start = 0;
  for (size_t bar = row.find('|'); bar != std::string::npos; bar = row.find('|', start)) {
    fields.push_back(row.substr(start, bar - start));
    start = bar + 1;
  }
  fields.push_back(row.substr(start));
  return fields;
}

class FullDiskTest : public ::testing::Test {
 protected:
  void SetUp() override {
    disk_ = dir_.path() / "disk";
    fs::create_directories(disk_);
    if (::mount("tmpfs", disk_.c_str(), "tmpfs", 0, "size=32m") != 0) {
      GTEST_SKIP() << "cannot mount a 32 MB tmpfs at " << disk_ << " (" << std::strerror(errno)
                   << "): the full-disk test needs root (CAP_SYS_ADMIN), as CI has";
    }
    mounted_ = true;
    data_ = disk_ / "data";
    port_ = server_.Start({"--port", "0", "--data", data_.string(), "--workers", "1",
                           "--threads-per-job", "1", "--min-free-mb", "4", "--web", ""},
                          dir_.path() / "server.log");
    client_ = MakeClient(port_);
  }

  void TearDown() override {
    if (!mounted_) return;
    client_.reset();
    server_.Kill(SIGTERM);
    EXPECT_EQ(server_.Wait(), 0);
    ::umount2(disk_.c_str(), MNT_DETACH);
  }

  // Takes the disk's free space down to `leave_bytes` with one file outside the data folder.
  void FillLeaving(int64_t leave_bytes) {
    const int64_t fill = FreeBytes(disk_) - leave_bytes;
    ASSERT_GT(fill, 0);
    std::ofstream filler(disk_ / "filler", std::ios::binary | std::ios::app);
    const std::string block(kMiB, 'x');
    for (int64_t written = 0; written < fill; written += kMiB) {
      filler.write(block.data(), std::min<int64_t>(kMiB, fill - written));
    }
    filler.close();
    ASSERT_TRUE(filler) << "cannot write the filler file";
  }

  // The database is sound, and every image and artifact it records is on disk with its size
  // and sha256.
  void ExpectConsistent() {
    const fs::path db = data_ / "omnirig.db";
    EXPECT_EQ(Query(db, "PRAGMA integrity_check"), std::vector<std::string>{"ok"});
    int files = 0;
    for (const std::string& row :
         Query(db, "SELECT dataset_id || '/images/' || name, size, sha256 FROM images")) {
      const auto fields = Split(row);
      const fs::path path = data_ / "datasets" / fields[0];
      ASSERT_TRUE(fs::exists(path)) << row;
      const storage::FileDigest digest = storage::DigestFile(path);
      EXPECT_EQ(std::to_string(digest.size), fields[1]) << row;
      EXPECT_EQ(digest.sha256, fields[2]) << row;
      ++files;
    }
    for (const std::string& row : Query(db, "SELECT path, size, sha256 FROM artifacts")) {
      const auto fields = Split(row);
      ASSERT_TRUE(fs::exists(data_ / fields[0])) << row;
      const storage::FileDigest digest = storage::DigestFile(data_ / fields[0]);
      EXPECT_EQ(std::to_string(digest.size), fields[1]) << row;
      EXPECT_EQ(digest.sha256, fields[2]) << row;
      ++files;
    }
    EXPECT_GT(files, 0);
  }

  // Regular files under the dataset's folder (uploads in progress included).
  int FilesOf(const std::string& dataset) {
    int count = 0;
    std::error_code error;
    for (const auto& entry :
         fs::recursive_directory_iterator(data_ / "datasets" / dataset, error)) {
      count += entry.is_regular_file();
    }
    return count;
  }

  TempDir dir_;
  fs::path disk_, data_;
  bool mounted_ = false;
  ServerProcess server_;
  int port_ = 0;
  std::unique_ptr<httplib::Client> client_;
};

TEST_F(FullDiskTest, UploadsAndJobsFailCleanlyAndWorkAgainWhenSpaceReturns) {
  const std::string dataset = JsonOf(
      client_->Post("/api/v1/datasets", R"({"name": "full"})", "application/json"))["id"];
  const std::string image_path = "/api/v1/datasets/" + dataset + "/images/";
  ASSERT_EQ(client_->Put((image_path + "a.png").c_str(), PngBytes(64, 48), "image/png")->status,
            201);
  const std::string sleep_params = R"({"steps": 1, "output_kb": 12288})";  // 12 MB of output
  const std::string job_body =
      R"({"type": "test_sleep", "dataset": ")" + dataset + R"(", "params": )" + sleep_params + "}";
  ASSERT_NO_FATAL_FAILURE(FillLeaving(7 * kMiB));

  // An upload the free space above the 4 MB reserve cannot hold: refused before it is read.
  const std::string big(4 * kMiB, 'p');
  const auto refused = client_->Put((image_path + "big.png").c_str(), big, "image/png");
  ASSERT_TRUE(refused);
  EXPECT_EQ(refused->status, 507) << refused->body;
  EXPECT_EQ(JsonOf(refused)["error"]["code"], "insufficient_storage") << refused->body;
  // One whose length is not announced (chunked) runs into the full disk while it is written;
  // it is a little longer than the free space, so the server reads the rest of it at once
  // (docs/http.md) and the client hears the answer.
  const size_t streamed_bytes = static_cast<size_t>(FreeBytes(disk_) + 2 * kMiB);
  const auto cut = client_->Put(
      (image_path + "streamed.png").c_str(),
      [&](size_t offset, httplib::DataSink& sink) {
        if (offset >= streamed_bytes) {
          sink.done();
        } else {
          sink.write(big.data(), std::min<size_t>(256 * 1024, streamed_bytes - offset));
        }
        return true;
      },
      "image/png");
  ASSERT_TRUE(cut);
  EXPECT_EQ(cut->status, 507) << cut->body;
  EXPECT_EQ(JsonOf(cut)["error"]["code"], "insufficient_storage") << cut->body;
  const json images = JsonOf(client_->Get(("/api/v1/datasets/" + dataset).c_str()))["images"];
  ASSERT_EQ(images.size(), 1u) << images.dump();
  EXPECT_EQ(FilesOf(dataset), 1);  // a.png alone: nothing partial

  // A job whose output does not fit: it fails, saying why, and the store records it.
  const auto created = client_->Post("/api/v1/jobs", job_body, "application/json");
  ASSERT_EQ(created->status, 202) << created->body;
  const std::string id = JsonOf(created)["id"];
  const json failed = WaitForJob(port_, id, 60);
  ASSERT_EQ(failed["state"], "failed") << failed.dump();
  EXPECT_EQ(failed["error"]["code"], "disk_full") << failed.dump();
  const std::string message = failed["error"]["message"];
  EXPECT_NE(message.find("disk holding the data folder is full"), std::string::npos) << message;
  EXPECT_NE(message.find("retry"), std::string::npos) << message;
  const json artifacts = JsonOf(client_->Get(("/api/v1/jobs/" + id + "/artifacts").c_str()));
  ASSERT_EQ(artifacts.size(), 1u) << artifacts.dump();
  EXPECT_EQ(artifacts[0]["name"], "log.txt");
  EXPECT_GE(FreeBytes(disk_), 4 * kMiB);  // its output is gone
  ASSERT_NO_FATAL_FAILURE(ExpectConsistent());

  // Space returns: the same server takes uploads and runs the retried job to the end.
  fs::remove(disk_ / "filler");
  const auto stored = client_->Put((image_path + "b.png").c_str(), PngBytes(640, 480), "image/png");
  EXPECT_EQ(stored->status, 201) << stored->body;
  const auto retried = client_->Post(("/api/v1/jobs/" + id + "/retry").c_str(), "", "");
  ASSERT_TRUE(retried);
  ASSERT_EQ(retried->status, 202) << retried->body;
  const json done = WaitForJob(port_, id, 60);
  ASSERT_EQ(done["state"], "succeeded") << done.dump();
  const auto out = client_->Get(("/api/v1/jobs/" + id + "/artifacts/out.bin").c_str());
  ASSERT_TRUE(out);
  EXPECT_EQ(storage::Sha256Hex(out->body), storage::Sha256Hex(SleepJobOutput(12288)));
  ASSERT_NO_FATAL_FAILURE(ExpectConsistent());
  int status = 0;
  EXPECT_EQ(::waitpid(server_.pid(), &status, WNOHANG), 0) << "the server exited";
}

}  // namespace
}  // namespace omnirig::testing

int main(int argc, char** argv) {
  int exit_code = 0;
  if (omnirig::testing::ServeIfRequested(argc, argv, exit_code)) return exit_code;
  // The streamed upload's client may still be writing when the server answers 507 and closes.
  signal(SIGPIPE, SIG_IGN);
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
