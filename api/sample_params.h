#pragma once
// The params of the "sample" job (api/sample_job.h): {"preset": "mono-calib" |
// "stereo-board" | "stereo-sequence"}.

#include <string>

#include <nlohmann/json.hpp>

namespace omnirig::api {

// The preset named by `params`; throws InvalidArgument naming the field otherwise.
std::string SamplePresetFromJson(const nlohmann::json& params);

}  // namespace omnirig::api
