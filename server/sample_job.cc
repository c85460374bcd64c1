#include "server/sample_job.h"

#include <algorithm>
#include <fstream>
#include <mutex>

#include "api/job_types.h"
#include "api/synth_json.h"
#include "engine/synth/presets.h"
#include "engine/util/check.h"
#include "storage/atomic_file.h"
#include "storage/image_header.h"

namespace omnirig::server {
namespace fs = std::filesystem;
namespace {

// Small renders: a first run should see its data within seconds on a laptop.
constexpr int kWidth = 640;
constexpr int kHeight = 480;
constexpr int kSupersampling = 2;

std::string PresetOf(const nlohmann::json& params) {
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

synth::RenderOptions Render(const api::JobContext& context) {
  synth::RenderOptions render;
  render.supersampling = kSupersampling;
  render.num_threads = std::max(1, context.num_threads);
  return render;
}

// Renders `preset` into `dir` with omnirig synth's writers (PNG images, ground_truth.json, and
// trajectory.tum for the sequence).
void RenderPreset(const std::string& preset, const api::JobContext& context,
                  const fs::path& dir) {
  const ProgressSink progress = api::SubRange(context.progress, 0.0, 0.95);
  if (preset == "mono-calib") {
    synth::MonoCalibrationOptions options;
    options.num_views = 8;
    options.width = kWidth;
    options.height = kHeight;
    options.render = Render(context);
    api::WriteMonoCalibrationSet(synth::MakeMonoCalibrationSet(options, progress), dir);
  } else if (preset == "stereo-board") {
    synth::StereoBoardOptions options;
    options.num_pairs = 8;
    options.width = kWidth;
    options.height = kHeight;
    options.render = Render(context);
    api::WriteStereoBoardSet(synth::MakeStereoBoardSet(options, progress), dir);
  } else {
    synth::StereoSequenceOptions options;
    options.num_frames = 10;
    options.path_length_m = 1.5;
    options.width = kWidth;
    options.height = kHeight;
    options.render = Render(context);
    api::WriteStereoSequence(synth::MakeStereoSequence(options, progress), "room", dir);
  }
}

// The record of a rendered file as an upload would make it (header probed, digest taken).
storage::ImageRecord RecordOf(const fs::path& path, const std::string& name) {
  std::string head(storage::kImageProbeBytes, '\0');
  std::ifstream in(path, std::ios::binary);
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<size_t>(in.gcount()));
  storage::ImageRecord record;
  record.name = name;
  if (path.extension() == ".tum") {
    record.content_type = "text/plain";
  } else {
    const storage::ImageHeader header = storage::ProbeImageHeader(head);
    if (header.status != storage::ImageHeader::Status::kOk) {
      throw std::runtime_error("rendered file " + name + " is not an image: " + header.problem);
    }
    record.width = header.width;
    record.height = header.height;
    record.content_type = header.content_type;
  }
  const storage::FileDigest digest = storage::DigestFile(path);
  record.size = digest.size;
  record.sha256 = digest.sha256;
  return record;
}

// Moves the rendered images (and trajectory.tum) into the dataset, with their records, under
// the lock that dataset deletion takes; returns how many files were added.
size_t AddToDataset(ServiceState& state, const std::string& dataset_id, const fs::path& dir) {
  std::vector<std::pair<fs::path, std::string>> files;  // rendered path, name in the dataset
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (!entry.is_regular_file()) continue;
    const std::string extension = entry.path().extension().string();
    if (extension != ".png" && extension != ".tum") continue;
    files.emplace_back(entry.path(), fs::relative(entry.path(), dir).generic_string());
  }
  std::sort(files.begin(), files.end());
  std::lock_guard<std::mutex> lock(state.files_mutex);
  if (!state.store->GetDataset(dataset_id)) {
    throw InvalidArgument("dataset " + dataset_id + " was deleted while the sample rendered");
  }
  const fs::path images_dir = state.data_dir->ImagesDir(dataset_id);
  std::vector<storage::ImageRecord> records;
  for (const auto& [path, name] : files) {
    records.push_back(RecordOf(path, name));
    fs::create_directories((images_dir / name).parent_path());
    fs::rename(path, images_dir / name);
    storage::FsyncPath((images_dir / name).parent_path());
  }
  state.store->PutImages(dataset_id, records);
  return records.size();
}

}  // namespace

void RegisterSampleJobType(ServiceState& state) {
  api::JobType type;
  type.name = "sample";
  type.validate = [](const nlohmann::json& params) { PresetOf(params); };
  type.reads_images = false;
  ServiceState* service = &state;
  type.run = [service](const nlohmann::json& params, const api::JobContext& context) {
    const std::string preset = PresetOf(params);
    // Rendered beside the artifacts; the images then move into the dataset, and
    // ground_truth.json stays as the job's artifact.
    const fs::path dir = context.output_dir / "sample";
    RenderPreset(preset, context, dir);
    context.progress.ThrowIfCancelled();
    context.progress.Report(0.95, "import", "adding the images to the dataset");
    const size_t count = AddToDataset(*service, context.dataset_id, dir);
    context.progress.Report(1.0, "done",
                            std::to_string(count) + " files of " + preset + " added to the dataset");
    return nlohmann::json{{"preset", preset},
                          {"num_files", count},
                          {"image_size", {kWidth, kHeight}},
                          {"ground_truth", "sample/ground_truth.json"}};
  };
  api::RegisterJobType(std::move(type));
}

}  // namespace omnirig::server
