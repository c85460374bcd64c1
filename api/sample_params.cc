#include "api/sample_params.h"

#include "engine/util/check.h"

namespace omnirig::api {

std::string SamplePresetFromJson(const nlohmann::json& params) {
  if (!params.is_object()) throw InvalidArgument("params must be an object");
  for (const auto& [key, value] : params.items()) {
    if (key != "preset") throw InvalidArgument("unknown field params." + key + " (only 'preset')");
  }
  // Not params.value("preset", ...): a preset of another type than a string would throw
  // nlohmann's type_error, answered as a 500.
  const auto it = params.find("preset");
  if (it != params.end() && !it->is_string()) {
    throw InvalidArgument("field 'params.preset' must be a string");
  }
  const std::string preset = it != params.end() ? it->get<std::string>() : std::string();
  if (preset != "mono-calib" && preset != "stereo-board" && preset != "stereo-sequence") {
    throw InvalidArgument(
        "params.preset must be mono-calib, stereo-board or stereo-sequence, got '" + preset + "'");
  }
  return preset;
}

}  // namespace omnirig::api
