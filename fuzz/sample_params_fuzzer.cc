// The "sample" job's params (api/sample_params.h), the input being their JSON text: accepted
// or refused with InvalidArgument (HTTP 400 invalid_params); any other exception would be a 500
// and is a failure here.

#include <cstddef>
#include <cstdint>
#include <string>

#include <nlohmann/json.hpp>

#include "engine/util/check.h"
#include "fuzz/fuzz_check.h"
#include "api/sample_params.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  // As api::ParseJsonBody: malformed JSON is a 400 before the params are looked at.
  const nlohmann::json params = nlohmann::json::parse(data, data + size, nullptr,
                                                      /*allow_exceptions=*/false);
  if (params.is_discarded()) return 0;
  try {
    const std::string preset = omnirig::api::SamplePresetFromJson(params);
    FUZZ_CHECK(preset == "mono-calib" || preset == "stereo-board" ||
               preset == "stereo-sequence");
  } catch (const omnirig::InvalidArgument&) {
  }
  return 0;
}
