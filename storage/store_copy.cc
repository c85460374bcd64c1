#include "storage/store_copy.h"

namespace omnirig::storage {

StoreCopyReport CopyStore(JobStore& from, JobStore& to) {
  StoreCopyReport report;
  for (const DatasetRecord& dataset : from.ListDatasets()) {
    if (!to.ImportDataset(dataset)) {
      ++report.datasets_skipped;
      continue;
    }
    const std::vector<ImageRecord> images = from.ListImages(dataset.id);
    to.PutImages(dataset.id, images);
    ++report.datasets;
    report.images += static_cast<int64_t>(images.size());
  }
  JobFilter all;
  all.limit = -1;
  std::vector<JobRecord> jobs = from.ListJobs(all);
  // Oldest first, so queued jobs keep their order in the destination's queue.
  for (auto job = jobs.rbegin(); job != jobs.rend(); ++job) {
    const std::vector<ArtifactRecord> artifacts = from.ListArtifacts(job->id);
    // The source service is stopped for the copy: a job it left running was interrupted, so its
    // lease counts as expired and the new store's workers re-queue it (attempt counted).
    JobRecord copy = *job;
    if (copy.state == JobState::kRunning) copy.lease_expires_at.reset();
    if (!to.ImportJob(copy, from.GetResult(job->id), artifacts)) {
      ++report.jobs_skipped;
      continue;
    }
    ++report.jobs;
    report.artifacts += static_cast<int64_t>(artifacts.size());
  }
  return report;
}

}  // namespace omnirig::storage
