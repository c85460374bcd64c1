#pragma once
// What the recording readers (recording_*.cc) share: the mapped bytes, a bounded little-endian
// reader whose errors name the file and the byte, decompression, and per-topic tallies. Not
// used outside storage/recording*.cc.

#include <cstdint>
#include <cstring>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <string_view>

#include "storage/recording.h"

namespace omnirig::storage::recording {

// A read-only mapping of a whole file (nothing is read until touched).
class MappedFile {
 public:
  explicit MappedFile(const std::filesystem::path& path);  // throws RecordingError
  ~MappedFile();
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;
  const uint8_t* data() const { return data_; }
  uint64_t size() const { return size_; }

 private:
  const uint8_t* data_ = nullptr;
  uint64_t size_ = 0;
};

// Bytes of one file of a recording: a whole mapped file or a member of a tar archive in one.
// `label` names it in errors ("run.bag", "run.tar:run/run_0.db3"); `file_offset` is where
// the bytes start in the file on disk, so that errors give offsets a hex editor finds.
struct Bytes {
  std::shared_ptr<const MappedFile> file;  // keeps the mapping alive
  const uint8_t* data = nullptr;
  uint64_t size = 0;
  uint64_t file_offset = 0;
  std::string label;
  std::filesystem::path path;  // the file on disk when the bytes are all of it, else empty
};

Bytes MapWhole(const std::filesystem::path& path, const std::string& label);

// Throws RecordingError "LABEL: byte N: PROBLEM" (N is the offset in the file on disk).
[[noreturn]] void Fail(const Bytes& bytes, uint64_t offset, const std::string& problem);

// Little-endian reads within [begin, end) of `bytes`; reading past `end` throws, naming `what`.
class Reader {
 public:
  Reader(const Bytes& bytes, uint64_t begin, uint64_t end)
      : bytes_(bytes), pos_(begin), end_(end) {}
  uint64_t pos() const { return pos_; }
  uint64_t end() const { return end_; }
  uint64_t left() const { return end_ - pos_; }
  void Need(uint64_t count, const char* what) const {
    if (count > left()) {
      Fail(bytes_, pos_,
           std::string(what) + " needs " + std::to_string(count) + " bytes but only " +
               std::to_string(left()) + " remain" + (end_ == bytes_.size ? " in the file" : ""));
    }
  }
  template <typename T>
  T Get(const char* what) {
    Need(sizeof(T), what);
    T value;
    std::memcpy(&value, bytes_.data + pos_, sizeof(T));  // the formats are little-endian, as is x86
    pos_ += sizeof(T);
    return value;
  }
  std::string_view View(uint64_t count, const char* what) {
    Need(count, what);
    std::string_view view(reinterpret_cast<const char*>(bytes_.data + pos_), count);
    pos_ += count;
    return view;
  }
  void Skip(uint64_t count, const char* what) { View(count, what); }

 private:
  const Bytes& bytes_;
  uint64_t pos_, end_;
};

// Decompresses `input` ("bz2", "lz4": the LZ4 frame format; "zstd") into `output`, which must
// come out at exactly `expected_size` bytes. Throws RecordingError naming the chunk at
// `offset` of `bytes` otherwise.
void Decompress(const std::string& compression, std::string_view input, uint64_t expected_size,
                std::string& output, const Bytes& bytes, uint64_t offset);

// Per-topic tallies while indexing, keyed by the container's own channel/connection id.
struct Tally {
  std::map<int64_t, RecordingTopic> topics;
  void Count(int64_t id, int64_t time_ns, int64_t count = 1) {
    RecordingTopic& topic = topics[id];
    if (topic.message_count == 0 || time_ns < topic.first_time_ns) topic.first_time_ns = time_ns;
    if (topic.message_count == 0 || time_ns > topic.last_time_ns) topic.last_time_ns = time_ns;
    topic.message_count += count;
  }
};

// Merges tallies into `index` by topic name (a topic split over several connections or files
// is one topic), sorted by name, with the total message count.
void AddTopics(const std::map<int64_t, RecordingTopic>& topics, RecordingIndex& index);

// The readers: each indexes on construction (throwing RecordingError) and reads messages.
std::unique_ptr<Recording> OpenRos1Bag(Bytes bytes);
std::unique_ptr<Recording> OpenMcap(Bytes bytes);
std::unique_ptr<Recording> OpenDb3(Bytes bytes);
// Throws unless `metadata` is a ROS 2 bag's metadata.yaml listing its files.
void CheckRos2Metadata(const Bytes& metadata);
// A ROS 2 bag from its metadata.yaml's text and a way to find the files it lists.
std::unique_ptr<Recording> OpenRos2Bag(const Bytes& metadata,
                                       const std::function<Bytes(const std::string&)>& file);

}  // namespace omnirig::storage::recording
