#include "api/job_types.h"

#include <fstream>
#include <memory>
#include <mutex>
#include <stdexcept>

#include "api/calibration_job.h"
#include "api/relpose_job.h"
#include "api/slam_job.h"
#include "api/stereo_job.h"
#include "engine/util/check.h"

namespace omnirig::api {

std::shared_ptr<const io::MessageSource> OpenJobRecording(const OpenRecording& open,
                                                          const std::string& name) {
  OMNIRIG_CHECK(open, "recordings are read by the service's jobs: upload the recording to a "
                      "dataset and submit the job there");
  return open(name);
}

void WriteTextFile(const std::filesystem::path& path, const std::string& text) {
  std::filesystem::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out << text;
  out.close();
  if (!out) throw std::runtime_error("cannot write " + path.filename().string());
}

void JobTypes::Add(JobType type) {
  std::lock_guard<std::mutex> lock(mutex_);
  std::unique_ptr<const JobType>& slot = types_[type.name];
  if (slot) replaced_.push_back(std::move(slot));
  slot = std::make_unique<const JobType>(std::move(type));
}

const JobType* JobTypes::Find(const std::string& name) const {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = types_.find(name);
  return it == types_.end() ? nullptr : it->second.get();
}

std::vector<std::string> JobTypes::Names() const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<std::string> names;
  for (const auto& [name, type] : types_) names.push_back(name);
  return names;
}

void AddBuiltinJobTypes(JobTypes* types) {
  types->Add(RelativePoseJobType());
  types->Add(CalibrationJobType());
  types->Add(StereoReconstructJobType());
  types->Add(SlamJobType());
}

}  // namespace omnirig::api
