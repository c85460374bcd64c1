#pragma once
// The data folder's layout and its start-up consistency check:
//
//   DATA/omnirig.db                              SQLite database (WAL: -wal, -shm beside it)
//   DATA/datasets/{dataset}/images/{name}        uploaded images (name may hold one folder)
//   DATA/jobs/{job}/attempt-{n}/...              each run's output folder (artifacts)
//   DATA/cache/...                               files derived from inputs, kept across jobs
//                                                and restarts, rebuilt when missing (e.g.
//                                                cache/rectification/: a rig's dense stereo
//                                                rectification tables, one file per rig)

#include <exception>
#include <filesystem>
#include <string>
#include <vector>

#include "storage/job_store.h"

namespace omnirig::storage {

class DataDir {
 public:
  // Creates the folder and its sub-folders when missing.
  explicit DataDir(std::filesystem::path root);

  const std::filesystem::path& root() const { return root_; }
  std::filesystem::path DatabasePath() const { return root_ / "omnirig.db"; }
  std::filesystem::path DatasetDir(const std::string& dataset_id) const;
  std::filesystem::path ImagesDir(const std::string& dataset_id) const;
  std::filesystem::path JobDir(const std::string& job_id) const;
  std::filesystem::path AttemptDir(const std::string& job_id, int attempt) const;
  std::filesystem::path CacheDir() const { return root_ / "cache"; }
  // Free bytes on the data folder's file system.
  int64_t FreeBytes() const;

 private:
  std::filesystem::path root_;
};

// Whether `error` says the disk is full: StoreFull, or a file write that failed with ENOSPC or
// EDQUOT (a std::system_error, as storage/'s file writers throw).
bool IsDiskFull(const std::exception& error);

// What the consistency check found and repaired.
struct ConsistencyReport {
  std::string integrity;                       // PRAGMA integrity_check: "ok" when healthy
  int temporary_files_removed = 0;             // leftovers of interrupted atomic writes
  std::vector<std::string> missing_images;     // "dataset/name": records dropped (re-upload)
  std::vector<std::string> missing_artifacts;  // "job/name": recorded but absent or resized
  int orphan_folders_removed = 0;              // dataset/job folders without a record
  bool ok() const { return integrity == "ok" && missing_artifacts.empty(); }
};

// Runs at start-up, before any worker: SQLite's integrity check, then files against records.
// Image records whose file is gone or has another size are dropped, so a client's resumed
// upload sends them again; folders of deleted datasets and jobs are removed.
ConsistencyReport CheckConsistency(const DataDir& data_dir, JobStore& store);

}  // namespace omnirig::storage
