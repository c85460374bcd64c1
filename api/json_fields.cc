#include "api/json_fields.h"

#include "engine/util/check.h"

namespace omnirig::api {

using nlohmann::json;

void CheckKnownFields(const json& object, const std::string& path,
                      const std::set<std::string>& known) {
  OMNIRIG_CHECK(object.is_object(), "'" << path << "' must be a JSON object");
  for (const auto& [key, value] : object.items()) {
    OMNIRIG_CHECK(known.count(key) > 0, "unknown field '" << path << "." << key << "'");
  }
}

namespace {

const json& Present(const json& object, const std::string& path, const std::string& key) {
  const auto it = object.find(key);
  OMNIRIG_CHECK(it != object.end(), "missing field '" << path << "." << key << "'");
  return *it;
}

}  // namespace

double NumberField(const json& object, const std::string& path, const std::string& key) {
  const json& value = Present(object, path, key);
  OMNIRIG_CHECK(value.is_number(), "field '" << path << "." << key << "' must be a number");
  return value.get<double>();
}

int IntegerField(const json& object, const std::string& path, const std::string& key) {
  const json& value = Present(object, path, key);
  OMNIRIG_CHECK(value.is_number_integer(),
                "field '" << path << "." << key << "' must be an integer");
  return value.get<int>();
}

bool BoolField(const json& object, const std::string& path, const std::string& key) {
  const json& value = Present(object, path, key);
  OMNIRIG_CHECK(value.is_boolean(), "field '" << path << "." << key << "' must be true or false");
  return value.get<bool>();
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
