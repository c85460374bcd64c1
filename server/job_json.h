#pragma once
// The job's JSON text (the form json_views.h documents) written straight into a string:
// the same bytes as nlohmann's dump() of the tree form (job_json_test.cc keeps that tree as
// its oracle and compares byte for byte), without building a JSON tree and without parsing
// the stored params back. A status poll is the service's most frequent request; building the
// tree, re-parsing params and dumping cost about half of its user-space CPU.

#include <optional>
#include <string>
#include <vector>

#include "storage/records.h"

namespace omnirig::server {

// Appends the job's JSON to `out`.
void AppendJobJson(const storage::JobRecord& job, std::string& out);
std::string JobJsonText(const storage::JobRecord& job);
// A JSON array of the jobs, in order.
std::string JobListJsonText(const std::vector<storage::JobRecord>& jobs);

// Building blocks, exposed for the test: each appends what nlohmann::json::dump() writes for
// the value (a UTC time is JSON null or api::TimeJson's ISO 8601 string).
void AppendJsonString(const std::string& value, std::string& out);
void AppendJsonNumber(double value, std::string& out);
void AppendJsonTime(const std::optional<double>& seconds_since_epoch, std::string& out);

}  // namespace omnirig::server
