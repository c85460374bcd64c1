// The service's request bodies (api/service_json.h): POST /api/v1/datasets and the envelope of
// POST /api/v1/jobs. Any text is parsed or refused with InvalidArgument (HTTP 400); any other
// exception would be a 500 and is a failure here.

#include <cstddef>
#include <cstdint>
#include <string>

#include "api/service_json.h"
#include "engine/util/check.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string body(reinterpret_cast<const char*>(data), size);
  try {
    omnirig::api::ParseCreateDatasetRequest(body);
  } catch (const omnirig::InvalidArgument&) {
  }
  try {
    const omnirig::api::CreateJobRequest request = omnirig::api::ParseCreateJobRequest(body);
    (void)request.params.dump();
  } catch (const omnirig::InvalidArgument&) {
  }
  return 0;
}
