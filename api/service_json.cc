#include "api/service_json.h"

#include <cmath>
#include <ctime>
#include <set>

#include "engine/util/check.h"

namespace omnirig::api {
namespace {

void RefuseUnknownFields(const nlohmann::json& object, const std::set<std::string>& known,
                         const std::string& what) {
  for (const auto& [key, value] : object.items()) {
    if (!known.count(key)) {
      std::string list;
      for (const std::string& name : known) list += (list.empty() ? "" : ", ") + name;
      throw InvalidArgument("unknown field '" + key + "' in " + what + " (known: " + list + ")");
    }
  }
}

std::string RequiredString(const nlohmann::json& object, const std::string& field) {
  const auto it = object.find(field);
  if (it == object.end()) throw InvalidArgument("missing field '" + field + "'");
  if (!it->is_string()) throw InvalidArgument("field '" + field + "' must be a string");
  return it->get<std::string>();
}

}  // namespace

nlohmann::json ParseJsonBody(const std::string& body) {
  nlohmann::json json;
  try {
    json = nlohmann::json::parse(body);
  } catch (const nlohmann::json::parse_error& e) {
    throw InvalidArgument(std::string("malformed JSON body: ") + e.what());
  }
  if (!json.is_object()) throw InvalidArgument("the request body must be a JSON object");
  return json;
}

CreateDatasetRequest ParseCreateDatasetRequest(const std::string& body) {
  const nlohmann::json json = ParseJsonBody(body);
  RefuseUnknownFields(json, {"name"}, "the dataset");
  CreateDatasetRequest request{RequiredString(json, "name")};
  if (request.name.empty() || request.name.size() > 200) {
    throw InvalidArgument("field 'name' must hold 1 to 200 characters");
  }
  return request;
}

CreateJobRequest ParseCreateJobRequest(const std::string& body) {
  const nlohmann::json json = ParseJsonBody(body);
  RefuseUnknownFields(json, {"type", "dataset", "params"}, "the job");
  CreateJobRequest request;
  request.type = RequiredString(json, "type");
  request.dataset = RequiredString(json, "dataset");
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
