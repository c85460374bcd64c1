#include "server/dataset_recordings.h"

#include <fstream>
#include <set>

#include "server/http.h"
#include "server/service.h"
#include "storage/recording.h"

namespace omnirig::server {
namespace {

namespace fs = std::filesystem;

std::string Lower(std::string text) {
  for (char& c : text) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

bool EndsWith(const std::string& text, const std::string& suffix) {
  return text.size() >= suffix.size() &&
         text.compare(text.size() - suffix.size(), suffix.size(), suffix) == 0;
}

std::string ContentType(const std::string& name) {
  const std::string lower = Lower(name);
  if (EndsWith(lower, ".bag")) return "application/x-rosbag";
  if (EndsWith(lower, ".mcap")) return "application/x-mcap";
  if (EndsWith(lower, ".tar")) return "application/x-tar";
  if (EndsWith(lower, ".db3")) return "application/vnd.sqlite3";
  return "application/yaml";  // metadata.yaml
}

double Seconds(int64_t time_ns) { return static_cast<double>(time_ns) * 1e-9; }

nlohmann::json IndexJson(const std::string& name, const storage::RecordingIndex& index) {
  nlohmann::json topics = nlohmann::json::array();
  for (const auto& topic : index.topics) {
    topics.push_back({{"name", topic.name},
                      {"type", topic.type},
                      {"encoding", topic.encoding},
                      {"message_count", topic.message_count},
                      {"first_stamp_s", Seconds(topic.first_time_ns)},
                      {"last_stamp_s", Seconds(topic.last_time_ns)},
                      {"rate_hz", topic.rate_hz()}});
  }
  nlohmann::json json = {{"name", name},
                         {"format", index.format},
                         {"message_count", index.message_count},
                         {"cut_short", index.cut_short},
                         {"topics", std::move(topics)}};
  if (!index.storage.empty()) json["storage"] = index.storage;
  if (!index.note.empty()) json["note"] = index.note;
  return json;
}

HttpError CorruptRecording(const std::string& name, const storage::RecordingError& error) {
  nlohmann::json details = {{"name", name}};
  if (!error.file().empty()) details["file"] = error.file();
  if (error.byte_offset()) details["byte_offset"] = *error.byte_offset();
  return HttpError(422, "corrupt_recording", error.what(), details);
}

// Where a recording's index is kept: recordings/{name}.json in the dataset's folder.
fs::path IndexPath(const ServiceState& state, const std::string& dataset_id,
                   const std::string& recording) {
  return state.data_dir->DatasetDir(dataset_id) / "recordings" / (recording + ".json");
}

// The folder of a ROS 2 bag a file belongs to ("run" for "run/metadata.yaml"), else empty.
std::string BagFolder(const std::string& name) {
  const size_t slash = name.find('/');
  if (slash == std::string::npos) return "";
  const std::string lower = Lower(name);
  if (EndsWith(lower, "/metadata.yaml") || EndsWith(lower, ".db3") || EndsWith(lower, ".mcap")) {
    return name.substr(0, slash);
  }
  return "";
}

// A ROS 2 bag's folder, indexed when every file its metadata.yaml lists is there.
nlohmann::json IndexFolder(const fs::path& images_dir, const std::string& folder) {
  try {
    return IndexJson(folder, storage::Recording::Open(images_dir / folder)->index());
  } catch (const storage::RecordingError& e) {
    return {{"name", folder}, {"format", "rosbag2"}, {"problem", e.what()}};
  }
}

}  // namespace

CheckedRecording CheckRecordingUpload(const std::string& name, const fs::path& path,
                                      const storage::FileDigest& digest) {
  CheckedRecording checked;
  checked.record = storage::ImageRecord{name, digest.size, digest.sha256, 0, 0, ContentType(name)};
  try {
    const auto index = storage::CheckRecordingFile(name, path);
    if (index) checked.index = IndexJson(name, *index);
  } catch (const storage::RecordingError& e) {
    throw CorruptRecording(name, e);
  }
  return checked;
}

void KeepRecordingIndex(ServiceState& state, const std::string& dataset_id,
                        const std::string& name, const CheckedRecording& checked) {
  const std::string folder = BagFolder(name);
  const fs::path images_dir = state.data_dir->ImagesDir(dataset_id);
  if (!folder.empty() && fs::exists(images_dir / folder / "metadata.yaml")) {
    storage::WriteFileAtomically(IndexPath(state, dataset_id, folder),
                                 IndexFolder(images_dir, folder).dump());
    return;
  }
  if (checked.index.is_object()) {
    storage::WriteFileAtomically(IndexPath(state, dataset_id, name), checked.index.dump());
  }
}

nlohmann::json RecordingsJson(const ServiceState& state, const std::string& dataset_id,
                              const std::vector<storage::ImageRecord>& images) {
  // A file of a ROS 2 bag's folder belongs to the folder's recording, not listed on its own.
  std::set<std::string> folders;
  for (const auto& image : images) {
    if (EndsWith(Lower(image.name), "/metadata.yaml")) folders.insert(BagFolder(image.name));
  }
  std::vector<std::string> names(folders.begin(), folders.end());
  for (const auto& image : images) {
    const std::string lower = Lower(image.name);
    const bool whole = EndsWith(lower, ".bag") || EndsWith(lower, ".mcap") || EndsWith(lower, ".tar");
    if (whole && !folders.count(BagFolder(image.name))) names.push_back(image.name);
  }
  nlohmann::json recordings = nlohmann::json::array();
  for (const auto& name : names) {
    std::ifstream in(IndexPath(state, dataset_id, name));
    nlohmann::json index = nlohmann::json::parse(in, nullptr, /*allow_exceptions=*/false);
    if (index.is_discarded()) {
      // Stored before this service indexed recordings, or lost in a crash: indexed on demand.
      index = {{"name", name}, {"problem", "not indexed yet: upload it again"}};
    }
    recordings.push_back(std::move(index));
  }
  return recordings;
}

}  // namespace omnirig::server
