#pragma once
// Recordings among a dataset's files (storage/recording.h): a ROS 1 .bag, an .mcap, or a ROS 2
// bag (its metadata.yaml and the .db3/.mcap files it lists, uploaded as files of one folder, or
// one .tar of that folder). Each file is checked when its upload is complete (422
// corrupt_recording naming what is wrong and where); a recording is indexed once, when whole,
// and its index kept beside the dataset (DATA/datasets/{id}/recordings/{name}.json) for the
// dataset's JSON: each recording with its topics (type, message count, first and last receive
// time in seconds, rate in Hz).

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "engine/io/recording_frames.h"
#include "storage/atomic_file.h"
#include "storage/records.h"

namespace omnirig::server {

struct ServiceState;

// A recording file checked at `path` (where its bytes are before they take the name `name`).
struct CheckedRecording {
  storage::ImageRecord record;  // width and height 0
  nlohmann::json index;         // a whole recording's listing; null for a part of a ROS 2 bag
};

// Throws HttpError 422 corrupt_recording (details: name, file, byte_offset when known).
CheckedRecording CheckRecordingUpload(const std::string& name, const std::filesystem::path& path,
                                      const storage::FileDigest& digest);

// After `checked` was put into place under `name` (under files_mutex): keeps a whole
// recording's index; for a file of a ROS 2 bag's folder, indexes the folder once every file
// its metadata.yaml lists is there (keeping what is wrong with it instead when it fails).
void KeepRecordingIndex(ServiceState& state, const std::string& dataset_id,
                        const std::string& name, const CheckedRecording& checked);

// The dataset's recordings, as the dataset's JSON lists them ("recordings").
nlohmann::json RecordingsJson(const ServiceState& state, const std::string& dataset_id,
                              const std::vector<storage::ImageRecord>& images);

// The names the dataset lists its recordings under, among its files' names: a .bag, .mcap or
// .tar by its file name, a ROS 2 bag's folder ("run" for "run/metadata.yaml") by the folder's.
std::vector<std::string> RecordingNames(const std::vector<std::string>& file_names);

// The dataset's recording `name` for a job (api::JobContext::open_recording): storage's reader
// behind the engine's MessageSource. Throws InvalidArgument naming the recordings the dataset
// holds when none has that name, and when the recording cannot be opened.
std::shared_ptr<const io::MessageSource> OpenDatasetRecording(
    const std::filesystem::path& images_dir, const std::vector<std::string>& file_names,
    const std::string& name);

}  // namespace omnirig::server
