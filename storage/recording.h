#pragma once
// Robot recordings read as they are written, with no ROS installed: the containers, not the
// messages. A recording yields, per topic, message records (topic, type, the type's hash or
// schema, receive time and the serialized bytes); decoding the bytes is the engine's
// (engine/io/image_message.h). The containers:
//
//   ROS 1 bag, format 2.0 ("#ROSBAG V2.0"): chunks uncompressed, bz2 or lz4 (ROS 1's "lz4" is
//       the LZ4 frame format). A bag whose recorder was killed has no index (its header's
//       index_pos is 0): it is read up to its last whole chunk and says so, as `rosbag reindex`
//       does (the unterminated chunk is dropped). A bag whose header names an index the file
//       does not reach was cut short in transfer: refused.
//   MCAP (https://mcap.dev/spec): records, chunks uncompressed, lz4 (frame) or zstd; the
//       summary section (channels, chunk indexes) when the writer wrote one, else a linear scan
//       of the data section. A file without its closing magic is refused (cut short).
//   ROS 2 bag: a folder holding metadata.yaml and the files it lists, .db3 (SQLite, rosbag2's
//       tables `topics` and `messages`) or .mcap; or one uncompressed .tar archive of it.
//
// The ROS 1 format is read directly rather than through Debian's librosbag-storage-dev: that
// package pulls in Boost (filesystem, regex, program_options, date_time), console_bridge,
// pluginlib, GPGME and roslz4 (about 430 packages with their dependencies, measured
// 2026-11-27 with apt-cache depends --recurse), for a format of seven record types that is
// published and fixed since 2010 (http://wiki.ros.org/Bags/Format/2.0).
//
// Files are mapped read-only (mmap), never copied whole into memory: an uncompressed message's
// bytes are a view into the mapping, a compressed chunk is decompressed into a buffer reused
// from chunk to chunk. Any structural fault throws RecordingError naming what is wrong and at
// which byte of which file.

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace omnirig::storage {

// A recording that is not one, is cut short or damaged: the message names the file, what is
// wrong and where (a byte offset or a record).
class RecordingError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
  RecordingError(const std::string& file, uint64_t byte_offset, const std::string& problem)
      : std::runtime_error(file + ": byte " + std::to_string(byte_offset) + ": " + problem),
        file_(file),
        byte_offset_(byte_offset) {}
  // The file (or archive member) and byte where a structural fault lies, when one does.
  const std::string& file() const { return file_; }
  const std::optional<uint64_t>& byte_offset() const { return byte_offset_; }

 private:
  std::string file_;
  std::optional<uint64_t> byte_offset_;
};

// True for names the service stores as (parts of) recordings: .bag, .mcap, .db3, .tar, and a
// ROS 2 bag's metadata.yaml (any case).
bool IsRecordingName(const std::string& name);

// One topic of a recording, with what one pass over the recording learned of it. Times are the
// recording's receive (log) times in nanoseconds since the Unix epoch; a message's own header
// stamp is the decoder's.
struct RecordingTopic {
  std::string name;        // "/cam0/image_raw"
  std::string type;        // as the recorder wrote it: "sensor_msgs/Image", "sensor_msgs/msg/Image"
  std::string encoding;    // "ros1" (ROS 1 serialization) or "cdr" (ROS 2)
  std::string type_hash;   // ROS 1's md5sum of the definition; empty otherwise
  std::string definition;  // the message definition when the container stores one
  int64_t message_count = 0;
  int64_t first_time_ns = 0, last_time_ns = 0;
  // Messages per second over the topic's span: (count - 1) / (last - first); 0 for < 2.
  double rate_hz() const;
};

struct RecordingIndex {
  std::string format;             // "rosbag1", "mcap", "rosbag2"
  std::string storage;            // rosbag2: "sqlite3" or "mcap"; otherwise empty
  std::vector<RecordingTopic> topics;  // sorted by name
  int64_t message_count = 0;
  bool cut_short = false;  // a ROS 1 bag without its index, read up to the cut
  std::string note;        // what was read when cut_short, else empty
};

// One message, valid only during the callback that receives it.
struct RecordingMessage {
  const RecordingTopic* topic = nullptr;
  int64_t log_time_ns = 0;
  std::string_view data;  // the serialized message
};

// The check of one uploaded file of a recording, at `path`, by the role its `name` gives it
// (see IsRecordingName): a .bag, .mcap or .tar is a whole recording, opened and indexed (its
// index returned); a .db3 must be SQLite with rosbag2's tables, intact; a metadata.yaml must be
// a ROS 2 bag's, listing its files (nullopt for these parts: the folder is indexed when whole).
// Throws RecordingError naming `name`, what is wrong and where.
std::optional<RecordingIndex> CheckRecordingFile(const std::string& name,
                                                 const std::filesystem::path& path);

class Recording {
 public:
  // Opens and indexes (one pass) a .bag, .mcap or .tar file, a ROS 2 bag's folder, or its
  // metadata.yaml. Throws RecordingError when it is no recording omnirig reads, is damaged or
  // is cut short (a ROS 1 bag cut short by its recorder is read, see above). Errors name the
  // file `label` (its file name when empty).
  static std::unique_ptr<Recording> Open(const std::filesystem::path& path,
                                         const std::string& label = "");
  virtual ~Recording() = default;

  const RecordingIndex& index() const { return index_; }
  const RecordingTopic* FindTopic(const std::string& name) const;

  // Calls `on_message` with each message of `topics` (every topic when empty), in the order the
  // recording stores them (receive order, as recorders write), until it returns false.
  // Throws RecordingError on damage the index pass did not see (e.g. a corrupt compressed
  // chunk) and std::invalid_argument for a topic the recording does not hold.
  void ReadMessages(const std::set<std::string>& topics,
                    const std::function<bool(const RecordingMessage&)>& on_message) const;

 protected:
  // Implementations: `wanted` holds indices into index().topics; return false to stop.
  virtual bool Read(const std::vector<bool>& wanted,
                    const std::function<bool(const RecordingMessage&)>& on_message) const = 0;
  RecordingIndex index_;
};

}  // namespace omnirig::storage
