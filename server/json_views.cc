#include "server/json_views.h"

#include "api/service_json.h"

namespace omnirig::server {

nlohmann::json DatasetJson(const storage::DatasetRecord& dataset) {
  return {{"id", dataset.id},
          {"name", dataset.name},
          {"created_at", api::TimeJson(dataset.created_at)},
          {"image_count", dataset.image_count},
          {"video_count", dataset.video_count},
          {"total_bytes", dataset.total_bytes}};
}

nlohmann::json DatasetJson(const storage::DatasetRecord& dataset,
                           const std::vector<storage::ImageRecord>& images) {
  nlohmann::json json = DatasetJson(dataset);
  json["images"] = nlohmann::json::array();
  for (const auto& image : images) json["images"].push_back(ImageJson(image));
  json["recordings"] = nlohmann::json::array();  // filled by GET /datasets/{id}
  return json;
}

nlohmann::json ImageJson(const storage::ImageRecord& image) {
  const size_t slash = image.name.find('/');
  // Only a header read at upload knows the size: videos and .tum files have none.
  const auto pixels = [&image](int value) {
    return image.width > 0 ? nlohmann::json(value) : nlohmann::json(nullptr);
  };
  return {{"name", image.name},
          {"camera", slash == std::string::npos ? nlohmann::json(nullptr)
                                                : nlohmann::json(image.name.substr(0, slash))},
          {"size", image.size},
          {"width", pixels(image.width)},
          {"height", pixels(image.height)},
          {"sha256", image.sha256},
          {"content_type", image.content_type}};
}

nlohmann::json JobJson(const storage::JobRecord& job) {
  nlohmann::json params = nlohmann::json::parse(job.params, nullptr, false);
  nlohmann::json json = {
      {"id", job.id},
      {"type", job.type},
      {"dataset", job.dataset_id},
      {"params", params.is_discarded() ? nlohmann::json(nullptr) : std::move(params)},
      {"state", storage::JobStateName(job.state)},
      {"progress",
       {{"fraction", job.progress.fraction},
        {"stage", job.progress.stage},
        {"message", job.progress.message},
        {"eta_s", job.progress.eta_s ? nlohmann::json(*job.progress.eta_s) : nullptr}}},
      {"created_at", api::TimeJson(job.created_at)},
      {"started_at", api::TimeJson(job.started_at)},
      {"finished_at", api::TimeJson(job.finished_at)},
      {"attempts", job.attempts},
      {"cancel_requested", job.cancel_requested},
      // The worker that ran (or runs) the job's last attempt ("HOST:PID"), null before any claim.
      {"worker", job.worker_id.empty() ? nlohmann::json(nullptr) : nlohmann::json(job.worker_id)},
      {"error", nullptr}};
  if (job.error) json["error"] = {{"code", job.error->code}, {"message", job.error->message}};
  return json;
}

nlohmann::json ArtifactJson(const storage::ArtifactRecord& artifact) {
  return {{"name", artifact.name},
          {"size", artifact.size},
          {"content_type", artifact.content_type},
          {"sha256", artifact.sha256}};
}

}  // namespace omnirig::server
