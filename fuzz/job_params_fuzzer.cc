// One job type's params (the "params" object of POST /api/v1/jobs), checked as the server
// checks them at submission: the type's validate() and referenced_jobs(). The input is the
// params' JSON text. Every params object is accepted or refused with InvalidArgument (HTTP 400
// invalid_params); any other exception would be a 500 and is a failure here.
//
// OMNIRIG_FUZZ_JOB_TYPE names the job type (compile definition, one target per type).

#include <cstddef>
#include <cstdint>
#include <string>

#include "api/job_types.h"
#include "api/service_json.h"
#include "engine/util/check.h"
#include "fuzz/fuzz_check.h"

namespace {

// The service's built-in job types, as a server holds them.
omnirig::api::JobTypes& Types() {
  static omnirig::api::JobTypes* types = [] {
    auto* built_in = new omnirig::api::JobTypes;
    omnirig::api::AddBuiltinJobTypes(built_in);
    return built_in;
  }();
  return *types;
}

void Validate(const nlohmann::json& params) {
  const omnirig::api::JobType* type = Types().Find(OMNIRIG_FUZZ_JOB_TYPE);
  FUZZ_CHECK(type != nullptr && type->validate);
  type->validate(params);
  if (type->referenced_jobs) {
    for (const omnirig::api::JobReference& reference : type->referenced_jobs(params)) {
      FUZZ_CHECK(!reference.field.empty());
    }
  }
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  Types();
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  nlohmann::json params;
  try {
    params = omnirig::api::ParseJsonBody(std::string(reinterpret_cast<const char*>(data), size));
  } catch (const omnirig::InvalidArgument&) {
    return 0;
  }
  try {
    Validate(params);
  } catch (const omnirig::InvalidArgument&) {
  }
  return 0;
}
