#include "api/job_types.h"

#include <fstream>
#include <memory>
#include <mutex>
#include <stdexcept>

#include "api/calibration_job.h"
#include "api/relpose_job.h"
#include "api/slam_job.h"
#include "api/stereo_job.h"

namespace omnirig::api {

void WriteTextFile(const std::filesystem::path& path, const std::string& text) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
  out.close();
  if (!out) throw std::runtime_error("cannot write " + path.filename().string());
}

namespace {

std::mutex& RegistryMutex() {
  static std::mutex mutex;
  return mutex;
}

std::map<std::string, std::unique_ptr<const JobType>>& Registry() {
  static std::map<std::string, std::unique_ptr<const JobType>> registry;
  return registry;
}

// Replaced entries are kept, never destroyed: FindJobType's pointers are used after the lock is
// released (by workers running a job), and the service registers the built-in types again each
// time one is constructed. A handful of entries per registration, for the process's lifetime.
std::vector<std::unique_ptr<const JobType>>& Retired() {
  static std::vector<std::unique_ptr<const JobType>> retired;
  return retired;
}

}  // namespace

void RegisterJobType(JobType type) {
  std::lock_guard<std::mutex> lock(RegistryMutex());
  std::unique_ptr<const JobType>& slot = Registry()[type.name];
  if (slot) Retired().push_back(std::move(slot));
  slot = std::make_unique<const JobType>(std::move(type));
}

const JobType* FindJobType(const std::string& name) {
  std::lock_guard<std::mutex> lock(RegistryMutex());
  const auto it = Registry().find(name);
  return it == Registry().end() ? nullptr : it->second.get();
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
