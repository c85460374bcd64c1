#pragma once
// Copies every record of one job store into another (`omnirig store copy`): datasets with their
// image records, jobs with their results and artifact records, ids, states, times and attempts
// kept. Files are not copied: records name them relative to the data folder, which moves as it
// is (or is mounted) under the new --data. Jobs left running count as interrupted (their lease
// expired). Records already in the destination are skipped, so a copy that stopped half-way can
// be run again.

#include <cstdint>

#include "storage/job_store.h"

namespace omnirig::storage {

struct StoreCopyReport {
  int64_t datasets = 0, images = 0, jobs = 0, artifacts = 0;  // copied
  int64_t datasets_skipped = 0, jobs_skipped = 0;             // already in the destination
};

StoreCopyReport CopyStore(JobStore& from, JobStore& to);

}  // namespace omnirig::storage
