#include "server/sample_job.h"

#include <algorithm>
#include <mutex>

#include "api/job_types.h"
#include "api/synth_json.h"
#include "server/sample_params.h"
#include "engine/synth/presets.h"
#include "engine/util/check.h"
#include "storage/atomic_file.h"

namespace omnirig::server {
namespace fs = std::filesystem;
namespace {

// Small renders: a first run should see its data within seconds on a laptop.
constexpr int kWidth = 640;
constexpr int kHeight = 480;
constexpr int kSupersampling = 2;

// A preset's options at the small size.
template <typename Options>
Options Small(const api::JobContext& context) {
  Options options;
  options.width = kWidth;
  options.height = kHeight;
  options.render.supersampling = kSupersampling;
  options.render.num_threads = std::max(1, context.num_threads);
  return options;
}

// Renders `preset` into `dir` with omnirig synth's writers (PNG images, ground_truth.json, and
// trajectory.tum for the sequence).
void RenderPreset(const std::string& preset, const api::JobContext& context,
                  const fs::path& dir) {
  const ProgressSink progress = api::SubRange(context.progress, 0.0, 0.95);
  if (preset == "mono-calib") {
    auto options = Small<synth::MonoCalibrationOptions>(context);
    options.num_views = 8;
    api::WriteMonoCalibrationSet(synth::MakeMonoCalibrationSet(options, progress), dir);
  } else if (preset == "stereo-board") {
    auto options = Small<synth::StereoBoardOptions>(context);
    options.num_pairs = 8;
    api::WriteStereoBoardSet(synth::MakeStereoBoardSet(options, progress), dir);
  } else {
    auto options = Small<synth::StereoSequenceOptions>(context);
    options.num_frames = 10;
    options.path_length_m = 1.5;
    api::WriteStereoSequence(synth::MakeStereoSequence(options, progress), "room", dir);
  }
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
    records.push_back(CheckCompleteFile(name, path));  // as an upload records it
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
  type.validate = [](const nlohmann::json& params) { SamplePresetFromJson(params); };
  type.reads_images = false;
  ServiceState* service = &state;
  type.run = [service](const nlohmann::json& params, const api::JobContext& context) {
    const std::string preset = SamplePresetFromJson(params);
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
