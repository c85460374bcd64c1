#include "server/dataset_recordings.h"

#include <algorithm>
#include <fstream>
#include <set>

#include "engine/util/check.h"
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

// A stored recording as the engine reads it.
class StoredRecording : public io::MessageSource {
 public:
  StoredRecording(std::string name, std::unique_ptr<storage::Recording> recording)
      : name_(std::move(name)), recording_(std::move(recording)) {
    for (const storage::RecordingTopic& topic : recording_->index().topics) {
      topics_.push_back({topic.name, topic.type, topic.encoding, topic.message_count});
    }
  }
  const std::string& name() const override { return name_; }
  const std::vector<io::RecordedTopic>& topics() const override { return topics_; }
  void ReadMessages(const std::set<std::string>& topics,
                    const std::function<bool(const io::RecordedMessage&)>& on_message)
      const override {
    const storage::RecordingTopic* first = recording_->index().topics.data();
    try {
      recording_->ReadMessages(topics, [&](const storage::RecordingMessage& message) {
        return on_message({&topics_[message.topic - first], message.data});
      });
    } catch (const storage::RecordingError& e) {
      throw InvalidArgument(std::string("recording ") + e.what());
    }
  }

 private:
  std::string name_;
  std::unique_ptr<storage::Recording> recording_;
  std::vector<io::RecordedTopic> topics_;
};

}  // namespace

std::vector<std::string> RecordingNames(const std::vector<std::string>& file_names) {
  // A file of a ROS 2 bag's folder belongs to the folder's recording, not listed on its own.
  std::set<std::string> folders;
  for (const auto& name : file_names) {
    if (EndsWith(Lower(name), "/metadata.yaml")) folders.insert(BagFolder(name));
  }
  std::vector<std::string> names(folders.begin(), folders.end());
  for (const auto& name : file_names) {
    const std::string lower = Lower(name);
    const bool whole = EndsWith(lower, ".bag") || EndsWith(lower, ".mcap") || EndsWith(lower, ".tar");
    if (whole && !folders.count(BagFolder(name))) names.push_back(name);
  }
  return names;
}

std::shared_ptr<const io::MessageSource> OpenDatasetRecording(
    const fs::path& images_dir, const std::vector<std::string>& file_names,
    const std::string& name) {
  const std::vector<std::string> names = RecordingNames(file_names);
  if (std::find(names.begin(), names.end(), name) == names.end()) {
    std::string list;
    for (const auto& known : names) list += (list.empty() ? "" : ", ") + known;
    throw InvalidArgument("the dataset holds no recording '" + name + "' (" +
                          (names.empty() ? "it holds no recording: upload a .bag, .mcap or ROS 2 bag"
                                         : "its recordings: " + list) +
                          ")");
  }
  try {
    return std::make_shared<StoredRecording>(name, storage::Recording::Open(images_dir / name, name));
  } catch (const storage::RecordingError& e) {
    throw InvalidArgument(std::string("recording ") + e.what());
  }
}

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
  std::vector<std::string> file_names;
  for (const auto& image : images) file_names.push_back(image.name);
  const std::vector<std::string> names = RecordingNames(file_names);
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
