#pragma once
// JSON forms of the stored records, with the names the API promises:
//   dataset:  {"id", "name", "created_at", "image_count", "total_bytes"[, "images": [image]]}
//   image:    {"name", "camera" (its folder, e.g. "cam0", or null), "size" (bytes), "width",
//              "height" (pixels, null when no header tells them: videos, .tum), "sha256",
//              "content_type"}
//   job:      {"id", "type", "dataset", "params", "state", "progress": {"fraction", "stage",
//              "message", "eta_s"}, "created_at", "started_at", "finished_at", "attempts",
//              "cancel_requested", "error": null | {"code", "message"}, "worker": null |
//              "HOST:PID" (who ran the last attempt)}
//   artifact: {"name", "size", "content_type", "sha256"}
// Times are ISO 8601 UTC strings (null when not reached yet).

#include <vector>

#include <nlohmann/json.hpp>

#include "storage/records.h"

namespace omnirig::server {

nlohmann::json DatasetJson(const storage::DatasetRecord& dataset);
nlohmann::json DatasetJson(const storage::DatasetRecord& dataset,
                           const std::vector<storage::ImageRecord>& images);
nlohmann::json ImageJson(const storage::ImageRecord& image);
// Stored params that are not JSON (not written by this service) show as null.
nlohmann::json JobJson(const storage::JobRecord& job);
nlohmann::json ArtifactJson(const storage::ArtifactRecord& artifact);

}  // namespace omnirig::server
