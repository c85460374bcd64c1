#include "server/sample_params.h"

#include "engine/util/check.h"

namespace omnirig::server {

std::string SamplePresetFromJson(const nlohmann::json& params) {
  if (!params.is_object()) throw InvalidArgument("params must be an object");
  for (const auto& [key, value] : params.items()) {
    if (key != "preset") throw InvalidArgument("unknown field params." + key + " (only 'preset')");
  }
  const std::string preset = params.value("preset", std::string());
  if (preset != "mono-calib" && preset != "stereo-board" && preset != "stereo-sequence") {
    throw InvalidArgument(
        "params.preset must be mono-calib, stereo-board or stereo-sequence, got '" + preset + "'");
  }
  return preset;
}

}  // namespace omnirig::server
