#include "api/sample_job.h"

#include <algorithm>
#include <utility>

#include "api/sample_params.h"
#include "api/synth_json.h"
#include "engine/synth/presets.h"
#include "engine/util/check.h"

namespace omnirig::api {
namespace fs = std::filesystem;
namespace {

// Small renders: a first run should see its data within seconds on a laptop.
constexpr int kWidth = 640;
constexpr int kHeight = 480;
constexpr int kSupersampling = 2;

// A preset's options at the small size.
template <typename Options>
Options Small(const JobContext& context) {
  Options options;
  options.width = kWidth;
  options.height = kHeight;
  options.render.supersampling = kSupersampling;
  options.render.num_threads = std::max(1, context.num_threads);
  return options;
}

// Renders `preset` into `dir` with omnirig synth's writers (PNG images, ground_truth.json, and
// trajectory.tum for the sequence).
void RenderPreset(const std::string& preset, const JobContext& context, const fs::path& dir) {
  const ProgressSink progress = SubRange(context.progress, 0.0, 0.95);
  if (preset == "mono-calib") {
    auto options = Small<synth::MonoCalibrationOptions>(context);
    options.num_views = 8;
    WriteMonoCalibrationSet(synth::MakeMonoCalibrationSet(options, progress), dir);
  } else if (preset == "stereo-board") {
    auto options = Small<synth::StereoBoardOptions>(context);
    options.num_pairs = 8;
    WriteStereoBoardSet(synth::MakeStereoBoardSet(options, progress), dir);
  } else {
    auto options = Small<synth::StereoSequenceOptions>(context);
    options.num_frames = 10;
    options.path_length_m = 1.5;
    WriteStereoSequence(synth::MakeStereoSequence(options, progress), "room", dir);
  }
}

}  // namespace

JobType SampleJobType(AddFilesToDataset add_files) {
  JobType type;
  type.name = "sample";
  type.validate = [](const nlohmann::json& params) { SamplePresetFromJson(params); };
  type.reads_images = false;
  type.run = [add_files = std::move(add_files)](const nlohmann::json& params,
                                                const JobContext& context) {
    const std::string preset = SamplePresetFromJson(params);
    // Rendered beside the artifacts; the images then move into the dataset, and
    // ground_truth.json stays as the job's artifact.
    const fs::path dir = context.output_dir / "sample";
    RenderPreset(preset, context, dir);
    context.progress.ThrowIfCancelled();
    context.progress.Report(0.95, "import", "adding the images to the dataset");
    const size_t count = add_files(context.dataset_id, dir);
    context.progress.Report(
        1.0, "done", std::to_string(count) + " files of " + preset + " added to the dataset");
    return nlohmann::json{{"preset", preset},
                          {"num_files", count},
                          {"image_size", {kWidth, kHeight}},
                          {"ground_truth", "sample/ground_truth.json"}};
  };
  return type;
}

}  // namespace omnirig::api
