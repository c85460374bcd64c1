#pragma once
// JSON request validation and shared JSON forms of the service API. Requests are
// checked strictly: unknown fields and wrong types are refused with InvalidArgument naming the
// field, which the server sends as HTTP 400.
//
//   POST /api/v1/datasets  {"name": string}
//   POST /api/v1/jobs      {"type": string, "dataset": string, "params": object}
//   errors                 {"error": {"code": string, "message": string, "details": object}}

#include <optional>
#include <string>

#include <nlohmann/json.hpp>

namespace omnirig::api {

struct CreateDatasetRequest {
  std::string name;
};

struct CreateJobRequest {
  std::string type;
  std::string dataset;
  nlohmann::json params = nlohmann::json::object();
};

// Parses a request body; throws InvalidArgument for malformed JSON, a body that is not an
// object, missing or mistyped fields, and unknown fields.
nlohmann::json ParseJsonBody(const std::string& body);
CreateDatasetRequest ParseCreateDatasetRequest(const std::string& body);
// Checks the envelope only; the job type's own validate() checks `params`.
CreateJobRequest ParseCreateJobRequest(const std::string& body);

// {"error": {"code", "message", "details"}}; details defaults to an empty object.
nlohmann::json ErrorJson(const std::string& code, const std::string& message,
                         const nlohmann::json& details = nlohmann::json::object());

// `json` as a response body's text. Strings holding invalid UTF-8 (a request's bytes quoted in
// an error message: a header, a file name, a path) have those bytes replaced by U+FFFD, where
// nlohmann's dump() would throw.
std::string JsonText(const nlohmann::json& json);

// ISO 8601 UTC with milliseconds ("2026-11-21T14:43:49.123Z") for seconds since the epoch;
// null when absent.
nlohmann::json TimeJson(std::optional<double> seconds_since_epoch);

}  // namespace omnirig::api
