#include "api/job_types.h"

#include <mutex>

#include "api/calibration_json.h"
#include "api/relpose_json.h"
#include "api/slam_json.h"
#include "api/stereo_json.h"

namespace omnirig::api {
namespace {

std::mutex& RegistryMutex() {
  static std::mutex mutex;
  return mutex;
}

std::map<std::string, JobType>& Registry() {
  static std::map<std::string, JobType> registry;
  return registry;
}

}  // namespace

void RegisterJobType(JobType type) {
  std::lock_guard<std::mutex> lock(RegistryMutex());
  const std::string name = type.name;
  Registry()[name] = std::move(type);
}

const JobType* FindJobType(const std::string& name) {
  std::lock_guard<std::mutex> lock(RegistryMutex());
  const auto it = Registry().find(name);
  return it == Registry().end() ? nullptr : &it->second;
}

std::vector<std::string> JobTypeNames() {
  std::lock_guard<std::mutex> lock(RegistryMutex());
  std::vector<std::string> names;
  for (const auto& [name, type] : Registry()) names.push_back(name);
  return names;
}

void RegisterBuiltinJobTypes() {
  // Each engine module's API file adds its registration here as it lands.
  RegisterRelativePoseJobType();
  RegisterCalibrationJobType();
  RegisterStereoReconstructJobType();
  RegisterSlamJobType();
}

}  // namespace omnirig::api
