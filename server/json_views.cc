#include "server/json_views.h"

#include "api/service_json.h"

namespace omnirig::server {

nlohmann::json DatasetJson(const storage::DatasetRecord& dataset) {
  return {{"id", dataset.id},
          {"name", dataset.name},
          {"created_at", api::TimeJson(dataset.created_at)},
          {"image_count", dataset.image_count},
          {"total_bytes", dataset.total_bytes}};
}

nlohmann::json DatasetJson(const storage::DatasetRecord& dataset,
                           const std::vector<storage::ImageRecord>& images) {
  nlohmann::json json = DatasetJson(dataset);
  json["images"] = nlohmann::json::array();
  for (const auto& image : images) json["images"].push_back(ImageJson(image));
  return json;
}

nlohmann::json ImageJson(const storage::ImageRecord& image) {
  return {{"name", image.name},     {"size", image.size},     {"width", image.width},
          {"height", image.height}, {"sha256", image.sha256}, {"content_type", image.content_type}};
}

nlohmann::json ArtifactJson(const storage::ArtifactRecord& artifact) {
  return {{"name", artifact.name},
          {"size", artifact.size},
          {"content_type", artifact.content_type},
          {"sha256", artifact.sha256}};
}

}  // namespace omnirig::server
