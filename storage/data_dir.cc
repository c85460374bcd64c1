#include "storage/data_dir.h"

#include <sys/statvfs.h>

#include <cerrno>
#include <set>
#include <system_error>

#include "storage/atomic_file.h"

namespace omnirig::storage {
namespace fs = std::filesystem;

DataDir::DataDir(fs::path root) : root_(std::move(root)) {
  fs::create_directories(root_ / "datasets");
  fs::create_directories(root_ / "jobs");
}

fs::path DataDir::DatasetDir(const std::string& dataset_id) const {
  return root_ / "datasets" / dataset_id;
}

fs::path DataDir::ImagesDir(const std::string& dataset_id) const {
  return DatasetDir(dataset_id) / "images";
}

fs::path DataDir::JobDir(const std::string& job_id) const { return root_ / "jobs" / job_id; }

fs::path DataDir::AttemptDir(const std::string& job_id, int attempt) const {
  return JobDir(job_id) / ("attempt-" + std::to_string(attempt));
}

bool IsDiskFull(const std::exception& error) {
  if (dynamic_cast<const StoreFull*>(&error)) return true;
  const auto* system = dynamic_cast<const std::system_error*>(&error);
  return system && (system->code() == std::errc::no_space_on_device ||
                    system->code() == std::error_code(EDQUOT, std::generic_category()));
}

int64_t DataDir::FreeBytes() const {
  struct statvfs stats {};
  if (::statvfs(root_.c_str(), &stats) != 0) return 0;
  return static_cast<int64_t>(stats.f_bavail) * static_cast<int64_t>(stats.f_frsize);
}

namespace {

int RemoveTemporaryFiles(const fs::path& root) {
  int removed = 0;
  std::error_code error;
  for (auto it = fs::recursive_directory_iterator(root, error);
       !error && it != fs::recursive_directory_iterator(); it.increment(error)) {
    if (it->is_regular_file() && IsTemporaryFileName(it->path().filename().string())) {
      std::error_code ignored;
      if (fs::remove(it->path(), ignored)) ++removed;
    }
  }
  return removed;
}

void CheckDatasets(const DataDir& data_dir, JobStore& store, ConsistencyReport& report) {
  std::set<std::string> known;
  for (const DatasetRecord& dataset : store.ListDatasets()) {
    known.insert(dataset.id);
    for (const ImageRecord& image : store.ListImages(dataset.id)) {
      const fs::path path = data_dir.ImagesDir(dataset.id) / image.name;
      std::error_code error;
      const auto size = fs::file_size(path, error);
      if (error || static_cast<int64_t>(size) != image.size) {
        store.DeleteImage(dataset.id, image.name);
        report.missing_images.push_back(dataset.id + "/" + image.name);
      }
    }
  }
  for (const auto& entry : fs::directory_iterator(data_dir.root() / "datasets")) {
    if (!known.count(entry.path().filename().string())) {
      fs::remove_all(entry.path());
      ++report.orphan_folders_removed;
    }
  }
}

void CheckJobs(const DataDir& data_dir, JobStore& store, ConsistencyReport& report) {
  std::set<std::string> known;
  JobFilter all;
  all.limit = -1;  // SQLite: no limit
  for (const JobRecord& job : store.ListJobs(all)) {
    known.insert(job.id);
    if (job.state != JobState::kSucceeded) continue;
    for (const ArtifactRecord& artifact : store.ListArtifacts(job.id)) {
      std::error_code error;
      const auto size = fs::file_size(data_dir.root() / artifact.path, error);
      if (error || static_cast<int64_t>(size) != artifact.size) {
        report.missing_artifacts.push_back(job.id + "/" + artifact.name);
      }
    }
  }
  for (const auto& entry : fs::directory_iterator(data_dir.root() / "jobs")) {
    if (!known.count(entry.path().filename().string())) {
      fs::remove_all(entry.path());
      ++report.orphan_folders_removed;
    }
  }
}

}  // namespace

ConsistencyReport CheckConsistency(const DataDir& data_dir, JobStore& store) {
  ConsistencyReport report;
  report.integrity = store.IntegrityCheck();
  report.temporary_files_removed = RemoveTemporaryFiles(data_dir.root());
  CheckDatasets(data_dir, store, report);
  CheckJobs(data_dir, store, report);
  return report;
}

}  // namespace omnirig::storage
