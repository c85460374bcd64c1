// ROS 1 bag format 2.0 (http://wiki.ros.org/Bags/Format/2.0), read directly (see recording.h
// for why not librosbag-storage). The file: the magic "#ROSBAG V2.0\n", a bag header record
// (padded to 4096 bytes) with index_pos, then chunks (op 0x05: connection records 0x07 and
// message records 0x02, compressed as a whole), each followed by index data records (0x04:
// per connection, the receive time and in-chunk offset of each of its messages), and at
// index_pos the connection records and chunk info records (0x06). A record is a header
// (u32 length, then fields "u32 length, name=value") and data (u32 length, bytes).
//
// Indexing a closed bag reads only the uncompressed index data records between chunks and the
// records at index_pos: no chunk is decompressed. A bag without index (index_pos 0: the
// recorder was killed) is read chunk by chunk up to the first unterminated one.

#include <map>
#include <set>
#include <vector>

#include "storage/recording_format.h"

namespace omnirig::storage::recording {
namespace {

constexpr uint8_t kOpMessage = 0x02, kOpBagHeader = 0x03, kOpIndexData = 0x04, kOpChunk = 0x05,
                  kOpChunkInfo = 0x06, kOpConnection = 0x07;
constexpr uint64_t kMagicSize = 13;

struct Record {
  uint64_t offset = 0;  // of the record's header length
  uint8_t op = 0;
  std::map<std::string_view, std::string_view> fields;
  uint64_t data_begin = 0, data_size = 0;
};

std::map<std::string_view, std::string_view> ParseFields(const Bytes& bytes, uint64_t begin,
                                                          uint64_t end) {
  std::map<std::string_view, std::string_view> fields;
  Reader reader(bytes, begin, end);
  while (reader.left() > 0) {
    const uint64_t at = reader.pos();
    const uint32_t length = reader.Get<uint32_t>("a header field's length");
    const std::string_view field = reader.View(length, "a header field");
    const size_t equals = field.find('=');
    if (equals == std::string_view::npos) Fail(bytes, at, "header field without '='");
    fields[field.substr(0, equals)] = field.substr(equals + 1);
  }
  return fields;
}

// One record at reader.pos() within the reader's bounds (whose errors say what was cut).
Record ReadRecord(const Bytes& bytes, Reader& reader) {
  Record record;
  record.offset = reader.pos();
  const uint32_t header_size = reader.Get<uint32_t>("a record's header length");
  reader.Need(header_size, "a record's header");
  record.fields = ParseFields(bytes, reader.pos(), reader.pos() + header_size);
  reader.Skip(header_size, "a record's header");
  record.data_size = reader.Get<uint32_t>("a record's data length");
  record.data_begin = reader.pos();
  reader.Skip(record.data_size, "a record's data");
  const auto op = record.fields.find("op");
  if (op == record.fields.end() || op->second.size() != 1) {
    Fail(bytes, record.offset, "record without a one-byte 'op' field");
  }
  record.op = static_cast<uint8_t>(op->second[0]);
  return record;
}

template <typename T>
T Field(const Bytes& bytes, const Record& record, const char* name) {
  const auto it = record.fields.find(name);
  if (it == record.fields.end() || it->second.size() != sizeof(T)) {
    Fail(bytes, record.offset, "record (op " + std::to_string(record.op) + ") lacks its " +
                                   std::to_string(sizeof(T)) + "-byte field '" + name + "'");
  }
  T value;
  std::memcpy(&value, it->second.data(), sizeof(T));
  return value;
}

std::string TextField(const Record& record, const char* name) {
  const auto it = record.fields.find(name);
  return it == record.fields.end() ? "" : std::string(it->second);
}

int64_t TimeNs(uint64_t packed) {  // u32 seconds then u32 nanoseconds, little-endian
  return static_cast<int64_t>(packed & 0xffffffffu) * 1000000000 + static_cast<int64_t>(packed >> 32);
}

struct Chunk {
  uint64_t offset = 0;  // of the chunk record
  std::string compression;
  uint64_t uncompressed_size = 0;
  uint64_t data_begin = 0, data_size = 0;
  std::set<uint32_t> connections;  // with messages in this chunk
};

class Ros1Bag : public Recording {
 public:
  explicit Ros1Bag(Bytes bytes) : bytes_(std::move(bytes)) {
    Reader reader(bytes_, kMagicSize, bytes_.size);
    const Record header = ReadRecord(bytes_, reader);
    if (header.op != kOpBagHeader) Fail(bytes_, kMagicSize, "the bag header record is missing");
    const uint64_t index_pos = Field<uint64_t>(bytes_, header, "index_pos");
    index_.format = "rosbag1";
    if (index_pos == 0) {
      ReindexCutShort(reader.pos());
    } else {
      if (index_pos > bytes_.size || index_pos < reader.pos()) {
        Fail(bytes_, bytes_.size,
             "the file ends here, but the bag header places its index at byte " +
                 std::to_string(index_pos) + ": the bag was cut short (e.g. in transfer)");
      }
      ReadIndexed(reader.pos(), index_pos, Field<uint32_t>(bytes_, header, "chunk_count"));
    }
    AddTopics(connections_, index_);
    for (const auto& [id, topic] : connections_) {
      topic_of_connection_[id] = FindTopic(topic.name);
    }
  }

 protected:
  bool Read(const std::vector<bool>& wanted,
            const std::function<bool(const RecordingMessage&)>& on_message) const override {
    std::string buffer;
    for (const Chunk& chunk : chunks_) {
      if (!std::any_of(chunk.connections.begin(), chunk.connections.end(),
                       [&](uint32_t id) { return Wanted(wanted, id); })) {
        continue;
      }
      Bytes inner = ChunkBytes(chunk, buffer);
      Reader reader(inner, 0, inner.size);
      while (reader.left() > 0) {
        const Record record = ReadRecord(inner, reader);
        if (record.op != kOpMessage) continue;
        const uint32_t id = Field<uint32_t>(inner, record, "conn");
        if (!Wanted(wanted, id)) continue;
        RecordingMessage message;
        message.topic = topic_of_connection_.at(id);
        message.log_time_ns = TimeNs(Field<uint64_t>(inner, record, "time"));
        message.data = std::string_view(reinterpret_cast<const char*>(inner.data + record.data_begin),
                                        record.data_size);
        if (!on_message(message)) return false;
      }
    }
    return true;
  }

 private:
  bool Wanted(const std::vector<bool>& wanted, uint32_t id) const {
    const auto it = topic_of_connection_.find(id);
    return it != topic_of_connection_.end() &&
           wanted[static_cast<size_t>(it->second - index_.topics.data())];
  }

  // The chunk's records as bytes: a view of the file, or decompressed into `buffer`. Offsets
  // in errors are then within the uncompressed chunk, which the label says.
  Bytes ChunkBytes(const Chunk& chunk, std::string& buffer) const {
    if (chunk.compression == "none") {
      if (chunk.data_size != chunk.uncompressed_size) {
        Fail(bytes_, chunk.offset, "uncompressed chunk of " + std::to_string(chunk.data_size) +
                                       " bytes declares " + std::to_string(chunk.uncompressed_size));
      }
      return Bytes{bytes_.file, bytes_.data + chunk.data_begin, chunk.data_size,
                   bytes_.file_offset + chunk.data_begin, bytes_.label, {}};
    }
    Decompress(chunk.compression,
               std::string_view(reinterpret_cast<const char*>(bytes_.data + chunk.data_begin),
                                chunk.data_size),
               chunk.uncompressed_size, buffer, bytes_, chunk.offset);
    return Bytes{nullptr, reinterpret_cast<const uint8_t*>(buffer.data()), buffer.size(), 0,
                 bytes_.label + " (" + chunk.compression + " chunk at byte " +
                     std::to_string(bytes_.file_offset + chunk.offset) + ", uncompressed)", {}};
  }

  Chunk ChunkOf(const Record& record) const {
    Chunk chunk;
    chunk.offset = record.offset;
    chunk.compression = TextField(record, "compression");
    chunk.uncompressed_size = Field<uint32_t>(bytes_, record, "size");
    chunk.data_begin = record.data_begin;
    chunk.data_size = record.data_size;
    return chunk;
  }

  void AddConnection(const Bytes& bytes, const Record& record) {
    const uint32_t id = Field<uint32_t>(bytes, record, "conn");
    if (connections_.count(id) && !connections_[id].name.empty()) return;
    const auto fields = ParseFields(bytes, record.data_begin, record.data_begin + record.data_size);
    const auto text = [&](const char* name) {
      const auto it = fields.find(name);
      return it == fields.end() ? std::string() : std::string(it->second);
    };
    RecordingTopic& topic = connections_[id];
    topic.name = TextField(record, "topic");
    topic.type = text("type");
    topic.encoding = "ros1";
    topic.type_hash = text("md5sum");
    topic.definition = text("message_definition");
    if (topic.name.empty() || topic.type.empty()) {
      Fail(bytes, record.offset, "connection record without topic or type");
    }
  }

  // A closed bag: the chunk section (chunks and their index data) ends exactly at index_pos;
  // after it, connection and chunk info records tile the file to its end.
  void ReadIndexed(uint64_t begin, uint64_t index_pos, uint32_t chunk_count) {
    Tally tally;
    Reader reader(bytes_, begin, index_pos);
    while (reader.left() > 0) {
      const Record record = ReadRecord(bytes_, reader);
      if (record.op == kOpChunk) {
        chunks_.push_back(ChunkOf(record));
      } else if (record.op == kOpIndexData) {
        if (chunks_.empty()) Fail(bytes_, record.offset, "index data record before any chunk");
        const uint32_t id = Field<uint32_t>(bytes_, record, "conn");
        const uint32_t count = Field<uint32_t>(bytes_, record, "count");
        if (Field<uint32_t>(bytes_, record, "ver") != 1 || uint64_t{count} * 12 != record.data_size) {
          Fail(bytes_, record.offset, "index data record (version 1, 12 bytes per message) is malformed");
        }
        Reader entries(bytes_, record.data_begin, record.data_begin + record.data_size);
        for (uint32_t i = 0; i < count; ++i) {
          const int64_t time_ns = TimeNs(entries.Get<uint64_t>("an index entry's time"));
          if (entries.Get<uint32_t>("an index entry's offset") >= chunks_.back().uncompressed_size) {
            Fail(bytes_, record.offset, "index entry points past the end of its chunk");
          }
          tally.Count(id, time_ns);
        }
        chunks_.back().connections.insert(id);
      } else {
        Fail(bytes_, record.offset, "record op " + std::to_string(record.op) +
                                        " where chunks and their index data belong");
      }
    }
    Reader index(bytes_, index_pos, bytes_.size);
    uint32_t chunk_infos = 0;
    while (index.left() > 0) {
      const Record record = ReadRecord(bytes_, index);
      if (record.op == kOpConnection) {
        AddConnection(bytes_, record);
      } else if (record.op == kOpChunkInfo) {
        ++chunk_infos;
      } else {
        Fail(bytes_, record.offset, "record op " + std::to_string(record.op) +
                                        " in the index section (connections and chunk infos)");
      }
    }
    if (chunk_infos != chunk_count || chunks_.size() != chunk_count) {
      Fail(bytes_, index_pos, "the bag header declares " + std::to_string(chunk_count) +
                                  " chunks, the file holds " + std::to_string(chunks_.size()) +
                                  " with " + std::to_string(chunk_infos) + " chunk infos");
    }
    for (const auto& [id, counted] : tally.topics) {
      if (!connections_.count(id)) {
        Fail(bytes_, index_pos, "messages of connection " + std::to_string(id) +
                                    " but no connection record for it");
      }
      RecordingTopic& topic = connections_[id];
      topic.message_count = counted.message_count;
      topic.first_time_ns = counted.first_time_ns;
      topic.last_time_ns = counted.last_time_ns;
    }
  }

  // Scans one whole chunk's records: its connections and messages.
  void ScanChunk(Chunk& chunk, Tally& tally) {
    std::string buffer;
    Bytes inner = ChunkBytes(chunk, buffer);
    Reader reader(inner, 0, inner.size);
    while (reader.left() > 0) {
      const Record record = ReadRecord(inner, reader);
      if (record.op == kOpConnection) {
        AddConnection(inner, record);
      } else if (record.op == kOpMessage) {
        const uint32_t id = Field<uint32_t>(inner, record, "conn");
        if (!connections_.count(id)) {
          Fail(inner, record.offset, "message of connection " + std::to_string(id) +
                                         " before its connection record");
        }
        tally.Count(id, TimeNs(Field<uint64_t>(inner, record, "time")));
        chunk.connections.insert(id);
      }
    }
  }

  // A bag whose recorder never wrote the index: every whole chunk, up to the first one the
  // recorder did not finish (its size still 0, or cut by the end of the file), which is dropped
  // with what follows it, as `rosbag reindex` does.
  void ReindexCutShort(uint64_t begin) {
    Tally tally;
    Reader reader(bytes_, begin, bytes_.size);
    uint64_t cut = bytes_.size;
    while (reader.left() > 0) {
      const uint64_t at = reader.pos();
      Record record;
      try {
        record = ReadRecord(bytes_, reader);
      } catch (const RecordingError&) {
        cut = at;
        break;
      }
      if (record.op == kOpChunk) {
        Chunk chunk = ChunkOf(record);
        if (chunk.data_size == 0 && chunk.uncompressed_size == 0) {
          cut = at;  // the recorder writes the sizes when it closes the chunk
          break;
        }
        ScanChunk(chunk, tally);
        chunks_.push_back(std::move(chunk));
      } else if (record.op == kOpConnection) {
        AddConnection(bytes_, record);
      }
    }
    for (const auto& [id, counted] : tally.topics) {
      RecordingTopic& topic = connections_[id];
      topic.message_count = counted.message_count;
      topic.first_time_ns = counted.first_time_ns;
      topic.last_time_ns = counted.last_time_ns;
    }
    int64_t messages = 0;
    for (const auto& [id, counted] : tally.topics) messages += counted.message_count;
    index_.cut_short = true;
    index_.note = "the bag has no index (its recorder did not close it): read " +
                  std::to_string(chunks_.size()) + " whole chunks, " + std::to_string(messages) +
                  " messages, up to byte " + std::to_string(bytes_.file_offset + cut) + " of " +
                  std::to_string(bytes_.file_offset + bytes_.size) +
                  (cut < bytes_.size ? "; the unfinished chunk there was dropped, as rosbag "
                                       "reindex drops it"
                                     : "");
  }

  Bytes bytes_;
  std::vector<Chunk> chunks_;
  std::map<int64_t, RecordingTopic> connections_;
  std::map<uint32_t, const RecordingTopic*> topic_of_connection_;
};

}  // namespace

std::unique_ptr<Recording> OpenRos1Bag(Bytes bytes) {
  return std::make_unique<Ros1Bag>(std::move(bytes));
}

}  // namespace omnirig::storage::recording
