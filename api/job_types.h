#pragma once
// The job types the service runs: the server knows job types only through this interface, and
// each job's API file provides its own.

#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "engine/io/recording_frames.h"
#include "engine/util/progress.h"
#include "engine/util/progress_range.h"

namespace omnirig::api {

// Opens a recording of the job's dataset by the name the dataset lists it under ("run.bag", a
// ROS 2 bag's folder "run"): the service's storage reads it, the job sees messages only.
// Throws InvalidArgument naming the dataset's recordings when it holds none of that name.
using OpenRecording =
    std::function<std::shared_ptr<const io::MessageSource>(const std::string& name)>;

// Opens `name` through `open`; throws InvalidArgument when the service gave no way to (a
// context outside the service, e.g. the CLI on a folder).
std::shared_ptr<const io::MessageSource> OpenJobRecording(const OpenRecording& open,
                                                          const std::string& name);

// Everything a job run sees of the service.
struct JobContext {
  std::string job_id;
  std::string dataset_id;
  std::filesystem::path dataset_dir;     // image files, by name (may hold cam0/, cam1/)
  std::vector<std::string> image_names;  // sorted names within dataset_dir
  std::filesystem::path output_dir;      // write artifacts here (files become artifacts)
  // Files derived from inputs and kept across jobs and processes (e.g. a rig's rectification
  // tables, cache_dir / "rectification"); empty: none are kept.
  std::filesystem::path cache_dir;
  int num_threads = 1;                   // the job's share of the cores
  ProgressSink progress;                 // progress + cancellation
  std::function<void(const std::string& line)> log;  // appended to the job's log artifact
  // Loads the result JSON of an earlier succeeded job (e.g. the calibrations a relative pose
  // job uses); throws InvalidArgument naming the job when it has none.
  std::function<nlohmann::json(const std::string& job_id)> load_result;
  OpenRecording open_recording;  // the dataset's recordings (params "recording")
  // The file of artifact `name` of an earlier succeeded job (e.g. the saved map a slam job
  // localises in); throws InvalidArgument naming the job and the artifact when it has none.
  std::function<std::filesystem::path(const std::string& job_id, const std::string& name)>
      artifact_path;

  // Appends a line to the job's log when the service gave it one.
  void Log(const std::string& line) const {
    if (log) log(line);
  }
  // Where the rigs' rectification tables are kept (SharedRectifier): cache_dir /
  // "rectification", empty without a cache_dir.
  std::filesystem::path RectificationTablesDir() const {
    return cache_dir.empty() ? std::filesystem::path() : cache_dir / "rectification";
  }
};

// Writes `text` to `path` (an artifact, an export), creating its folder; throws
// std::runtime_error naming the file when it cannot.
void WriteTextFile(const std::filesystem::path& path, const std::string& text);

// A job a job reads: its id, the type it must have (empty: any) and the parameter naming it.
struct JobReference {
  std::string id;
  std::string type;
  std::string field;  // e.g. "rig"
  bool operator==(const JobReference& other) const {
    return id == other.id && type == other.type && field == other.field;
  }
};

// What the server knows of a job's inputs at submission (JobType::check_inputs): the dataset's
// files with the image sizes read from their headers at upload (0 for videos and other files),
// and the referenced jobs' results.
struct SubmissionInputs {
  struct Image {
    std::string name;
    int width = 0, height = 0;
  };
  std::string dataset_id;
  std::filesystem::path dataset_dir;  // the files, by name
  std::vector<Image> images;          // sorted by name
  std::vector<std::string> file_names() const {
    std::vector<std::string> names;
    for (const Image& image : images) names.push_back(image.name);
    return names;
  }
  // The result JSON of a referenced job (found succeeded before check_inputs runs); throws
  // InvalidArgument when it has none.
  std::function<nlohmann::json(const std::string& job_id)> load_result;
  OpenRecording open_recording;  // the dataset's recordings (params "recording")
};

struct JobType {
  std::string name;
  // Validates `params` at submission; throws InvalidArgument with a message naming the field.
  std::function<void(const nlohmann::json& params)> validate;
  // Earlier jobs this job reads, each with the type it must have (e.g. "relative_pose" for a
  // job that reads a rig): the server refuses, at submission, a reference to a missing job
  // (404), to a job of another type or one that has not succeeded (422). Optional.
  std::function<std::vector<JobReference>(const nlohmann::json& params)> referenced_jobs;
  // Checks at submission, without decoding pixels, that the dataset's files fit `params` and
  // the referenced jobs' results (e.g. images of another size than the rig's calibration, a
  // slam job's videos that do not open, pair or match the rig: what the files' headers tell);
  // runs on an HTTP thread after the references were found succeeded. Throws InvalidArgument
  // with the reason (the server answers 422 invalid_input, the code of a job that fails on
  // its input while running). Optional.
  std::function<void(const nlohmann::json& params, const SubmissionInputs& inputs)>
      check_inputs;
  // Whether the job reads its dataset's images (the server then refuses an empty dataset with
  // 422 at submission instead of queueing a job that can only fail).
  bool reads_images = true;
  // Runs the job and returns its result JSON. Throws omnirig::Cancelled on cancellation,
  // InvalidArgument for bad input discovered while running, anything else for failures.
  std::function<nlohmann::json(const nlohmann::json& params, const JobContext& context)> run;
};

// The job types a service runs, by name. The service owns one and passes it to its routes and
// workers; each job type's API file provides its JobType (e.g. RelativePoseJobType()).
// Thread-safe: a type may be added while workers look types up (tests replace one while the
// service runs).
class JobTypes {
 public:
  // Adds `type`; one of the same name is replaced for Find, while pointers Find returned before
  // stay valid (and unchanged) for this object's lifetime, for a job that is running.
  void Add(JobType type);
  // nullptr when no such type.
  const JobType* Find(const std::string& name) const;
  std::vector<std::string> Names() const;

 private:
  mutable std::mutex mutex_;
  std::map<std::string, std::unique_ptr<const JobType>> types_;
  std::vector<std::unique_ptr<const JobType>> replaced_;
};

// Adds every job type omnirig ships that needs nothing of the service (all but "sample",
// which adds to the service's datasets: api/sample_job.h).
void AddBuiltinJobTypes(JobTypes* types);

}  // namespace omnirig::api
