#include "api/json_fields.h"

#include <limits>

#include "engine/util/check.h"

namespace omnirig::api {

using nlohmann::json;

std::string FieldName(const std::string& path, const std::string& key) {
  return path.empty() ? key : path + "." + key;
}

void CheckKnownFields(const json& object, const std::string& path,
                      const std::set<std::string>& known) {
  OMNIRIG_CHECK(object.is_object(), "'" << path << "' must be a JSON object");
  for (const auto& [key, value] : object.items()) {
    OMNIRIG_CHECK(known.count(key) > 0, "unknown field '" << FieldName(path, key) << "'");
  }
}

const json& Field(const json& object, const std::string& path, const std::string& key) {
  const auto it = object.find(key);
  OMNIRIG_CHECK(it != object.end(), "missing field '" << FieldName(path, key) << "'");
  return *it;
}

double NumberField(const json& object, const std::string& path, const std::string& key) {
  const json& value = Field(object, path, key);
  OMNIRIG_CHECK(value.is_number(), "field '" << FieldName(path, key) << "' must be a number");
  return value.get<double>();
}

int IntegerField(const json& object, const std::string& path, const std::string& key) {
  const json& value = Field(object, path, key);
  OMNIRIG_CHECK(value.is_number_integer(),
                "field '" << FieldName(path, key) << "' must be an integer");
  // get<int>() would wrap a larger value into range.
  const bool fits = value.is_number_unsigned()
                        ? value.get<uint64_t>() <= std::numeric_limits<int>::max()
                        : value.get<int64_t>() >= std::numeric_limits<int>::min() &&
                              value.get<int64_t>() <= std::numeric_limits<int>::max();
  OMNIRIG_CHECK(fits, "field '" << FieldName(path, key) << "' is out of range");
  return value.get<int>();
}

bool BoolField(const json& object, const std::string& path, const std::string& key) {
  const json& value = Field(object, path, key);
  OMNIRIG_CHECK(value.is_boolean(), "field '" << FieldName(path, key) << "' must be true or false");
  return value.get<bool>();
}

std::string StringField(const json& object, const std::string& path, const std::string& key) {
  const json& value = Field(object, path, key);
  OMNIRIG_CHECK(value.is_string(), "field '" << FieldName(path, key) << "' must be a string");
  return value.get<std::string>();
}

std::string JobIdField(const json& object, const std::string& path, const std::string& key) {
  const json& value = Field(object, path, key);
  OMNIRIG_CHECK(value.is_string() && !value.get<std::string>().empty(),
                "field '" << FieldName(path, key) << "' must be a job id (a non-empty string)");
  return value.get<std::string>();
}

void ReadNumberArray(const json& value, const std::string& name, int size, double* out) {
  OMNIRIG_CHECK(value.is_array() && value.size() == static_cast<size_t>(size),
                "field '" << name << "' must be an array of " << size << " numbers");
  for (int i = 0; i < size; ++i) {
    OMNIRIG_CHECK(value[i].is_number(), "field '" << name << "' must hold numbers only");
    out[i] = value[i].get<double>();
  }
}

void ReadNumber(const json& object, const std::string& path, const std::string& key,
                double* value) {
  if (object.contains(key)) *value = NumberField(object, path, key);
}

void ReadInteger(const json& object, const std::string& path, const std::string& key, int* value) {
  if (object.contains(key)) *value = IntegerField(object, path, key);
}

void ReadBool(const json& object, const std::string& path, const std::string& key, bool* value) {
  if (object.contains(key)) *value = BoolField(object, path, key);
}

std::set<std::string> KeysOf(const OptionTable& table) {
  std::set<std::string> keys;
  for (const OptionField& field : table) keys.insert(field.key);
  return keys;
}

void ReadOptions(const json& object, const std::string& path, const OptionTable& table) {
  for (const OptionField& field : table) {
    if (auto* d = std::get_if<double*>(&field.value)) ReadNumber(object, path, field.key, *d);
    if (auto* i = std::get_if<int*>(&field.value)) ReadInteger(object, path, field.key, *i);
    if (auto* b = std::get_if<bool*>(&field.value)) ReadBool(object, path, field.key, *b);
  }
}

json OptionsToJson(const OptionTable& table) {
  json out = json::object();
  for (const OptionField& field : table) {
    std::visit([&](auto* value) { out[field.key] = *value; }, field.value);
  }
  return out;
}

}  // namespace omnirig::api
