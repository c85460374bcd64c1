// ROS 2 bags (rosbag2): a folder whose metadata.yaml lists its files (relative_file_paths) and
// their storage (storage_identifier: sqlite3 or mcap). A .db3 file is SQLite with rosbag2's
// tables: topics(id, name, type, serialization_format, offered_qos_profiles, ...) and
// messages(id, topic_id, timestamp, data), timestamp the receive time in nanoseconds. Its
// messages are read in id (recording) order; an .mcap file of a ROS 2 bag is plain MCAP.

#include <sqlite3.h>

#include <map>
#include <sstream>

#include "storage/recording_format.h"

namespace omnirig::storage::recording {
namespace {

// A read-only SQLite connection: to the file itself (immutable: no journal, no locks), or to
// the bytes of a tar member, deserialized in place (SQLite reads them, never copies them).
class Db3Connection {
 public:
  explicit Db3Connection(const Bytes& bytes) : bytes_(bytes) {
    if (!bytes.path.empty()) {
      const std::string uri = "file:" + bytes.path.string() + "?immutable=1";
      Check(sqlite3_open_v2(uri.c_str(), &db_, SQLITE_OPEN_READONLY | SQLITE_OPEN_URI, nullptr),
            "cannot open");
      return;
    }
    if (bytes.size > 19 && bytes.data[18] == 2) {
      Fail(bytes, 18, "a .db3 in WAL mode cannot be read from inside a .tar: upload the bag's "
                      "folder (its files) instead");
    }
    Check(sqlite3_open_v2(":memory:", &db_, SQLITE_OPEN_READWRITE, nullptr), "cannot open");
    Check(sqlite3_deserialize(db_, "main", const_cast<unsigned char*>(bytes.data),
                              static_cast<sqlite3_int64>(bytes.size),
                              static_cast<sqlite3_int64>(bytes.size), SQLITE_DESERIALIZE_READONLY),
          "cannot read");
  }
  ~Db3Connection() { sqlite3_close(db_); }
  Db3Connection(const Db3Connection&) = delete;
  Db3Connection& operator=(const Db3Connection&) = delete;

  void Check(int status, const std::string& what) const {
    if (status == SQLITE_OK || status == SQLITE_ROW || status == SQLITE_DONE) return;
    throw RecordingError(bytes_.label + ": " + what + ": " +
                         (db_ ? sqlite3_errmsg(db_) : sqlite3_errstr(status)) +
                         " (not a whole rosbag2 .db3: damaged or cut short)");
  }

  // Runs `sql`, calling `row` for each result row.
  template <typename Row>
  void Query(const std::string& sql, const Row& row) const {
    sqlite3_stmt* statement = nullptr;
    Check(sqlite3_prepare_v2(db_, sql.c_str(), -1, &statement, nullptr), "cannot query");
    int status;
    try {
      while ((status = sqlite3_step(statement)) == SQLITE_ROW) {
        if (!row(statement)) {
          status = SQLITE_DONE;
          break;
        }
      }
    } catch (...) {
      sqlite3_finalize(statement);
      throw;
    }
    sqlite3_finalize(statement);
    Check(status, "cannot read");
  }

 private:
  const Bytes& bytes_;
  sqlite3* db_ = nullptr;
};

std::string Column(sqlite3_stmt* statement, int column) {
  const unsigned char* text = sqlite3_column_text(statement, column);
  return text ? reinterpret_cast<const char*>(text) : "";
}

class Db3 : public Recording {
 public:
  explicit Db3(Bytes bytes) : bytes_(std::move(bytes)), db_(bytes_) {
    index_.format = "rosbag2";
    index_.storage = "sqlite3";
    CheckSize();
    int tables = 0;
    db_.Query("SELECT name FROM sqlite_master WHERE type = 'table' AND name IN ('topics', "
              "'messages')",
              [&](sqlite3_stmt*) { return ++tables, true; });
    if (tables != 2) {
      throw RecordingError(bytes_.label + ": an SQLite file without rosbag2's tables 'topics' "
                           "and 'messages'");
    }
    std::map<int64_t, RecordingTopic> topics;
    db_.Query("SELECT id, name, type, serialization_format FROM topics", [&](sqlite3_stmt* row) {
      RecordingTopic& topic = topics[sqlite3_column_int64(row, 0)];
      topic.name = Column(row, 1);
      topic.type = Column(row, 2);
      topic.encoding = Column(row, 3);
      return true;
    });
    db_.Query("SELECT topic_id, COUNT(*), MIN(timestamp), MAX(timestamp) FROM messages GROUP BY "
              "topic_id",
              [&](sqlite3_stmt* row) {
                const int64_t id = sqlite3_column_int64(row, 0);
                if (!topics.count(id)) {
                  throw RecordingError(bytes_.label + ": messages of topic_id " +
                                       std::to_string(id) + ", which table 'topics' lacks");
                }
                RecordingTopic& topic = topics[id];
                topic.message_count = sqlite3_column_int64(row, 1);
                topic.first_time_ns = sqlite3_column_int64(row, 2);
                topic.last_time_ns = sqlite3_column_int64(row, 3);
                return true;
              });
    AddTopics(topics, index_);
    for (const auto& [id, topic] : topics) topic_of_id_[id] = FindTopic(topic.name);
  }

 protected:
  bool Read(const std::vector<bool>& wanted,
            const std::function<bool(const RecordingMessage&)>& on_message) const override {
    std::string ids;
    for (const auto& [id, topic] : topic_of_id_) {
      if (!wanted[static_cast<size_t>(topic - index_.topics.data())]) continue;
      ids += (ids.empty() ? "" : ", ") + std::to_string(id);
    }
    if (ids.empty()) return true;
    bool more = true;
    db_.Query("SELECT topic_id, timestamp, data FROM messages WHERE topic_id IN (" + ids +
                  ") ORDER BY id",
              [&](sqlite3_stmt* row) {
                RecordingMessage message;
                message.topic = topic_of_id_.at(sqlite3_column_int64(row, 0));
                message.log_time_ns = sqlite3_column_int64(row, 1);
                const void* blob = sqlite3_column_blob(row, 2);
                message.data = std::string_view(static_cast<const char*>(blob),
                                                static_cast<size_t>(sqlite3_column_bytes(row, 2)));
                more = on_message(message);
                return more;
              });
    return more;
  }

 private:
  // A file cut short (in transfer, or by a recorder killed before SQLite synced) holds fewer
  // pages than its header declares. Checked from the header alone: SQLite's own quick_check
  // reads every page (the whole file, at a fifth of the speed of indexing); damage inside the
  // tables shows when the queries below walk them.
  void CheckSize() const {
    if (bytes_.size < 100) Fail(bytes_, bytes_.size, "the file ends inside SQLite's header");
    const uint8_t* header = bytes_.data;
    uint64_t page_size = (uint64_t{header[16]} << 8) | header[17];
    if (page_size == 1) page_size = 65536;
    const uint64_t pages = (uint64_t{header[28]} << 24) | (uint64_t{header[29]} << 16) |
                           (uint64_t{header[30]} << 8) | header[31];
    // The page count is valid when the change counter (24) equals version-valid-for (92):
    // SQLite before 3.7 left it stale.
    if (page_size < 512 || pages == 0 || std::memcmp(header + 24, header + 92, 4) != 0) return;
    if (pages * page_size > bytes_.size) {
      Fail(bytes_, bytes_.size,
           "the file ends here, but its header declares " + std::to_string(pages) + " pages of " +
               std::to_string(page_size) + " bytes (" + std::to_string(pages * page_size) +
               "): it was cut short");
    }
  }

  Bytes bytes_;
  Db3Connection db_;
  std::map<int64_t, const RecordingTopic*> topic_of_id_;
};

// The values of metadata.yaml that locate the bag's files; rosbag2 writes it as block YAML
// ("key: value", lists as "- item" lines), which a line reader covers.
struct Metadata {
  std::string storage_identifier;
  std::string compression_format;
  std::vector<std::string> relative_file_paths;
};

std::string Unquote(std::string value) {
  while (!value.empty() && (value.back() == ' ' || value.back() == '\r')) value.pop_back();
  while (!value.empty() && value.front() == ' ') value.erase(0, 1);
  if (value.size() >= 2 && (value.front() == '\'' || value.front() == '"') &&
      value.back() == value.front()) {
    value = value.substr(1, value.size() - 2);
  }
  return value;
}

Metadata ParseMetadata(const Bytes& bytes) {
  const std::string text(reinterpret_cast<const char*>(bytes.data), bytes.size);
  if (text.find("rosbag2_bagfile_information:") == std::string::npos) {
    throw RecordingError(bytes.label + ": not a ROS 2 bag's metadata.yaml (no "
                         "rosbag2_bagfile_information)");
  }
  Metadata metadata;
  std::istringstream lines(text);
  std::string line;
  bool in_paths = false;
  size_t paths_indent = 0;
  while (std::getline(lines, line)) {
    const size_t indent = line.find_first_not_of(' ');
    if (indent == std::string::npos) continue;
    const std::string content = line.substr(indent);
    if (in_paths && content.rfind("- ", 0) == 0 && indent >= paths_indent) {
      metadata.relative_file_paths.push_back(Unquote(content.substr(2)));
      continue;
    }
    in_paths = false;
    const size_t colon = content.find(':');
    if (colon == std::string::npos) continue;
    const std::string key = content.substr(0, colon);
    const std::string value = Unquote(content.substr(colon + 1));
    if (key == "storage_identifier") metadata.storage_identifier = value;
    if (key == "compression_format") metadata.compression_format = value;
    if (key == "relative_file_paths") {
      in_paths = true;
      paths_indent = indent;
    }
  }
  if (metadata.relative_file_paths.empty()) {
    throw RecordingError(bytes.label + ": metadata.yaml lists no relative_file_paths");
  }
  if (!metadata.compression_format.empty()) {
    throw RecordingError(bytes.label + ": the bag's files are compressed (" +
                         metadata.compression_format + "); omnirig reads uncompressed ROS 2 bags "
                         "(`ros2 bag convert` writes one)");
  }
  return metadata;
}

// The bag's files, one after the other, as one recording.
class Ros2Bag : public Recording {
 public:
  explicit Ros2Bag(std::vector<std::unique_ptr<Recording>> files) : files_(std::move(files)) {
    index_.format = "rosbag2";
    for (const auto& file : files_) {
      std::map<int64_t, RecordingTopic> topics;
      for (const auto& topic : file->index().topics) topics[static_cast<int64_t>(topics.size())] = topic;
      AddTopics(topics, index_);
      const std::string storage = file->index().format == "mcap" ? "mcap" : file->index().storage;
      if (index_.storage.empty()) index_.storage = storage;
      if (index_.storage != storage) index_.storage = "mixed";
    }
  }

 protected:
  bool Read(const std::vector<bool>& wanted,
            const std::function<bool(const RecordingMessage&)>& on_message) const override {
    for (const auto& file : files_) {
      std::set<std::string> names;
      for (size_t i = 0; i < wanted.size(); ++i) {
        if (wanted[i] && file->FindTopic(index_.topics[i].name)) names.insert(index_.topics[i].name);
      }
      if (names.empty()) continue;
      bool more = true;
      file->ReadMessages(names, [&](const RecordingMessage& message) {
        RecordingMessage ours = message;
        ours.topic = FindTopic(message.topic->name);
        more = on_message(ours);
        return more;
      });
      if (!more) return false;
    }
    return true;
  }

 private:
  std::vector<std::unique_ptr<Recording>> files_;
};

}  // namespace

std::unique_ptr<Recording> OpenDb3(Bytes bytes) { return std::make_unique<Db3>(std::move(bytes)); }

void CheckRos2Metadata(const Bytes& metadata) { ParseMetadata(metadata); }

std::unique_ptr<Recording> OpenRos2Bag(const Bytes& metadata_bytes,
                                       const std::function<Bytes(const std::string&)>& file) {
  const Metadata metadata = ParseMetadata(metadata_bytes);
  std::vector<std::unique_ptr<Recording>> files;
  for (const auto& relative : metadata.relative_file_paths) {
    Bytes bytes = file(relative);
    if (bytes.size >= 8 && std::memcmp(bytes.data, "\x89MCAP0\r\n", 8) == 0) {
      files.push_back(OpenMcap(std::move(bytes)));
    } else if (bytes.size >= 16 && std::memcmp(bytes.data, "SQLite format 3", 16) == 0) {
      files.push_back(OpenDb3(std::move(bytes)));
    } else {
      Fail(bytes, 0, "neither SQLite (.db3) nor MCAP, the storages of ROS 2 bags omnirig reads");
    }
  }
  return std::make_unique<Ros2Bag>(std::move(files));
}

}  // namespace omnirig::storage::recording
