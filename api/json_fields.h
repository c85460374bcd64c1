#pragma once

// Readers of one field of a request's JSON object, shared by the job types' params parsers.
// Their messages name the field by its path ("field 'params.block_size' must be an integer"):
// those words are what a client reads in a 400, so they are the same for every job type.

#include <set>
#include <string>
#include <variant>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "engine/util/check.h"
#include "engine/util/error_prefix.h"

namespace omnirig::api {

// "PATH.KEY", or KEY alone where PATH is empty (the top level of a request body or a result).
std::string FieldName(const std::string& path, const std::string& key);

// Refuses a value that is not an object ("'PATH' must be a JSON object") and any key not in known.
void CheckKnownFields(const nlohmann::json& object, const std::string& path,
                      const std::set<std::string>& known);

// PATH.KEY, which must be present ("missing field 'PATH.KEY'"). An integer must fit an int.
const nlohmann::json& Field(const nlohmann::json& object, const std::string& path,
                            const std::string& key);
double NumberField(const nlohmann::json& object, const std::string& path, const std::string& key);
int IntegerField(const nlohmann::json& object, const std::string& path, const std::string& key);
bool BoolField(const nlohmann::json& object, const std::string& path, const std::string& key);
std::string StringField(const nlohmann::json& object, const std::string& path,
                        const std::string& key);
// The id of another job: a non-empty string.
std::string JobIdField(const nlohmann::json& object, const std::string& path,
                       const std::string& key);

// `value`, named `name` in messages, as an array of `size` numbers into out[0..size).
void ReadNumberArray(const nlohmann::json& value, const std::string& name, int size, double* out);
template <int N>
Eigen::Matrix<double, N, 1> NumberVector(const nlohmann::json& value, const std::string& name) {
  Eigen::Matrix<double, N, 1> out;
  ReadNumberArray(value, name, N, out.data());
  return out;
}

// The optional forms: *value keeps its default when PATH.KEY is absent.
void ReadNumber(const nlohmann::json& object, const std::string& path, const std::string& key,
                double* value);
void ReadInteger(const nlohmann::json& object, const std::string& path, const std::string& key,
                 int* value);
void ReadBool(const nlohmann::json& object, const std::string& path, const std::string& key,
              bool* value);

// One tunable of an options struct: its JSON key and where it lives in one instance. A table of
// these is at once the options' known keys, their reader and their echo in a job's result.
struct OptionField {
  std::string key;
  std::variant<double*, int*, bool*> value;
};
using OptionTable = std::vector<OptionField>;

std::set<std::string> KeysOf(const OptionTable& table);
// Reads each field of table that object holds, in the table's order, with the messages above.
void ReadOptions(const nlohmann::json& object, const std::string& path, const OptionTable& table);
nlohmann::json OptionsToJson(const OptionTable& table);

}  // namespace omnirig::api
