#pragma once
// JSON forms of the stored records, as issue 6 names them:
//   dataset:  {"id", "name", "created_at", "image_count", "total_bytes"[, "images": [image]]}
//   image:    {"name", "size", "width", "height", "sha256", "content_type"}
//   job:      {"id", "type", "dataset", "params", "state", "progress": {"fraction", "stage",
//              "message", "eta_s"}, "created_at", "started_at", "finished_at", "attempts",
//              "cancel_requested", "error": null | {"code", "message"}, "worker": null |
//              "HOST:PID" (issue 18: who ran the last attempt)}
//   artifact: {"name", "size", "content_type", "sha256"}
// Times are ISO 8601 UTC strings (null when not reached yet). The job's form is written as text
// by job_json.h (the status poll's hot path); its test holds the tree form as the oracle.

#include <vector>

#include <nlohmann/json.hpp>

#include "storage/records.h"

namespace omnirig::server {

nlohmann::json DatasetJson(const storage::DatasetRecord& dataset);
nlohmann::json DatasetJson(const storage::DatasetRecord& dataset,
                           const std::vector<storage::ImageRecord>& images);
nlohmann::json ImageJson(const storage::ImageRecord& image);
nlohmann::json ArtifactJson(const storage::ArtifactRecord& artifact);

}  // namespace omnirig::server
