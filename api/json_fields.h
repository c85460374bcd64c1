#pragma once

// Readers of one field of a request's JSON object, shared by the job types' params parsers.
// Their messages name the field by its path ("field 'params.block_size' must be an integer"):
// those words are what a client reads in a 400, so they are the same for every job type.

#include <set>
#include <string>

#include <nlohmann/json.hpp>

namespace omnirig::api {

// Refuses a value that is not an object ("'PATH' must be a JSON object") and any key not in known.
void CheckKnownFields(const nlohmann::json& object, const std::string& path,
                      const std::set<std::string>& known);

// PATH.KEY, which must be present ("missing field 'PATH.KEY'").
double NumberField(const nlohmann::json& object, const std::string& path, const std::string& key);
int IntegerField(const nlohmann::json& object, const std::string& path, const std::string& key);
bool BoolField(const nlohmann::json& object, const std::string& path, const std::string& key);

// The optional forms: *value keeps its default when PATH.KEY is absent.
void ReadNumber(const nlohmann::json& object, const std::string& path, const std::string& key,
                double* value);
void ReadInteger(const nlohmann::json& object, const std::string& path, const std::string& key,
                 int* value);
void ReadBool(const nlohmann::json& object, const std::string& path, const std::string& key,
              bool* value);

}  // namespace omnirig::api
