#include "api/service_json.h"

#include <cmath>
#include <ctime>

#include "api/json_fields.h"
#include "engine/util/check.h"

namespace omnirig::api {

nlohmann::json ParseJsonBody(const std::string& body) {
  nlohmann::json json;
  try {
    json = nlohmann::json::parse(body);
  } catch (const nlohmann::json::exception& e) {
    // parse_error, and out_of_range for a number beyond a double's range (1e999).
    throw InvalidArgument(std::string("malformed JSON body: ") + e.what());
  }
  if (!json.is_object()) throw InvalidArgument("the request body must be a JSON object");
  return json;
}

CreateDatasetRequest ParseCreateDatasetRequest(const std::string& body) {
  const nlohmann::json json = ParseJsonBody(body);
  CheckKnownFields(json, "", {"name"});
  CreateDatasetRequest request{StringField(json, "", "name")};
  if (request.name.empty() || request.name.size() > 200) {
    throw InvalidArgument("field 'name' must hold 1 to 200 characters");
  }
  return request;
}

CreateJobRequest ParseCreateJobRequest(const std::string& body) {
  const nlohmann::json json = ParseJsonBody(body);
  CheckKnownFields(json, "", {"type", "dataset", "params"});
  CreateJobRequest request;
  request.type = StringField(json, "", "type");
  request.dataset = StringField(json, "", "dataset");
  if (const auto it = json.find("params"); it != json.end()) {
    if (!it->is_object()) throw InvalidArgument("field 'params' must be an object");
    request.params = *it;
  }
  return request;
}

nlohmann::json ErrorJson(const std::string& code, const std::string& message,
                         const nlohmann::json& details) {
  return {{"error", {{"code", code}, {"message", message}, {"details", details}}}};
}

std::string JsonText(const nlohmann::json& json) {
  return json.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
}

nlohmann::json TimeJson(std::optional<double> seconds_since_epoch) {
  if (!seconds_since_epoch) return nullptr;
  const double seconds = std::floor(*seconds_since_epoch);
  const std::time_t whole = static_cast<std::time_t>(seconds);
  const int millis = std::min(999, static_cast<int>((*seconds_since_epoch - seconds) * 1000));
  std::tm utc{};
  gmtime_r(&whole, &utc);
  char text[40];
  const size_t length = std::strftime(text, sizeof(text), "%Y-%m-%dT%H:%M:%S", &utc);
  std::snprintf(text + length, sizeof(text) - length, ".%03dZ", millis);
  return std::string(text);
}

}  // namespace omnirig::api
