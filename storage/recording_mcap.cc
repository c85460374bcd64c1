// MCAP, read to its published specification (https://mcap.dev/spec, version 0): the magic
// "\x89MCAP0\r\n" at both ends; between them records "u8 opcode, u64 length, content": a Header,
// the data section (Schemas, Channels, Messages, Chunks each followed by its Message Index
// records, ...) closed by Data End, an optional summary section (Schemas and Channels repeated,
// Chunk Indexes, Statistics, ...), and the Footer (summary_start, summary_offset_start,
// summary_crc). Strings are "u32 length, bytes"; maps "u32 byte length, entries".
//
// Indexing walks the data section's top-level records (a chunk is skipped over, O(1)) and takes
// the receive (log) times of a chunk's messages from the Message Index records that follow it;
// only a chunk without them is decompressed and scanned. Schemas and channels come from the
// summary section when the writer wrote one (its CRC checked), and from the data section.

#include <zlib.h>

#include <map>
#include <set>
#include <vector>

#include "storage/recording_format.h"

namespace omnirig::storage::recording {
namespace {

constexpr uint8_t kHeader = 0x01, kFooter = 0x02, kSchema = 0x03, kChannel = 0x04,
                  kMessage = 0x05, kChunk = 0x06, kMessageIndex = 0x07, kDataEnd = 0x0f;
constexpr uint64_t kMagicSize = 8;
constexpr uint64_t kFooterSize = 1 + 8 + 20;

struct Record {
  uint64_t offset = 0;  // of the opcode
  uint8_t op = 0;
  uint64_t begin = 0, end = 0;  // content
};

Record NextRecord(Reader& reader) {
  Record record;
  record.offset = reader.pos();
  record.op = reader.Get<uint8_t>("a record's opcode");
  const uint64_t length = reader.Get<uint64_t>("a record's length");
  record.begin = reader.pos();
  reader.Skip(length, "a record's content");
  record.end = reader.pos();
  return record;
}

std::string String(Reader& reader, const char* what) {
  const uint32_t size = reader.Get<uint32_t>(what);
  return std::string(reader.View(size, what));
}

struct Schema {
  std::string name, encoding, data;
};

// A place messages are read from, in file order: a chunk, or a message outside any chunk.
struct Item {
  Record record;
  std::set<uint16_t> channels;  // a chunk's channels (empty for a bare message)
};

class Mcap : public Recording {
 public:
  explicit Mcap(Bytes bytes) : bytes_(std::move(bytes)) {
    index_.format = "mcap";
    const uint64_t size = bytes_.size;
    if (size < 2 * kMagicSize + kFooterSize ||
        std::memcmp(bytes_.data + size - kMagicSize, "\x89MCAP0\r\n", kMagicSize) != 0) {
      Fail(bytes_, size, "the file does not end with MCAP's closing magic: it was cut short "
                         "(a writer that was never closed, or an incomplete transfer)");
    }
    const uint64_t footer = size - kMagicSize - kFooterSize;
    Reader reader(bytes_, footer, size - kMagicSize);
    const Record record = NextRecord(reader);
    if (record.op != kFooter) Fail(bytes_, footer, "no Footer record before the closing magic");
    Reader fields(bytes_, record.begin, record.end);
    const uint64_t summary_start = fields.Get<uint64_t>("the footer's summary_start");
    fields.Get<uint64_t>("the footer's summary_offset_start");
    const uint32_t summary_crc = fields.Get<uint32_t>("the footer's summary_crc");
    if (summary_start != 0) ReadSummary(summary_start, footer, summary_crc);
    ScanData(summary_start != 0 ? summary_start : footer);
    Tally tally;
    for (Item& item : items_) CountItem(item, tally);
    const auto all_known = [&] {
      return std::all_of(tally.topics.begin(), tally.topics.end(),
                         [&](const auto& entry) { return channels_.count(entry.first) > 0; });
    };
    if (!all_known()) FindChannelsInChunks();  // no summary, channels only inside chunks
    for (const auto& [id, counted] : tally.topics) {
      if (!channels_.count(id)) {
        Fail(bytes_, 0, "messages on channel " + std::to_string(id) + ", which no Channel "
                        "record describes");
      }
    }
    for (auto& [id, topic] : channels_) {
      if (tally.topics.count(id)) {
        const RecordingTopic& counted = tally.topics.at(id);
        topic.message_count = counted.message_count;
        topic.first_time_ns = counted.first_time_ns;
        topic.last_time_ns = counted.last_time_ns;
      }
    }
    AddTopics(channels_, index_);
    for (const auto& [id, topic] : channels_) topic_of_channel_[id] = FindTopic(topic.name);
  }

 protected:
  bool Read(const std::vector<bool>& wanted,
            const std::function<bool(const RecordingMessage&)>& on_message) const override {
    const auto is_wanted = [&](uint16_t id) {
      const auto it = topic_of_channel_.find(id);
      return it != topic_of_channel_.end() &&
             wanted[static_cast<size_t>(it->second - index_.topics.data())];
    };
    std::string buffer;
    for (const Item& item : items_) {
      if (item.record.op == kMessage) {
        if (!Deliver(bytes_, item.record, is_wanted, on_message)) return false;
        continue;
      }
      if (!std::any_of(item.channels.begin(), item.channels.end(), is_wanted)) continue;
      const Bytes inner = ChunkRecords(item.record, buffer);
      Reader reader(inner, 0, inner.size);
      while (reader.left() > 0) {
        const Record record = NextRecord(reader);
        if (record.op == kMessage && !Deliver(inner, record, is_wanted, on_message)) return false;
      }
    }
    return true;
  }

 private:
  template <typename IsWanted>
  bool Deliver(const Bytes& bytes, const Record& record, const IsWanted& is_wanted,
               const std::function<bool(const RecordingMessage&)>& on_message) const {
    Reader reader(bytes, record.begin, record.end);
    const uint16_t channel = reader.Get<uint16_t>("a message's channel_id");
    if (!is_wanted(channel)) return true;
    reader.Get<uint32_t>("a message's sequence");
    RecordingMessage message;
    message.topic = topic_of_channel_.at(channel);
    message.log_time_ns = static_cast<int64_t>(reader.Get<uint64_t>("a message's log_time"));
    reader.Get<uint64_t>("a message's publish_time");
    message.data = reader.View(reader.left(), "a message's data");
    return on_message(message);
  }

  void ReadSchema(const Bytes& bytes, const Record& record) {
    Reader reader(bytes, record.begin, record.end);
    const uint16_t id = reader.Get<uint16_t>("a schema's id");
    Schema schema;
    schema.name = String(reader, "a schema's name");
    schema.encoding = String(reader, "a schema's encoding");
    schema.data = String(reader, "a schema's data");
    schemas_[id] = std::move(schema);
  }

  void ReadChannel(const Bytes& bytes, const Record& record) {
    Reader reader(bytes, record.begin, record.end);
    const uint16_t id = reader.Get<uint16_t>("a channel's id");
    const uint16_t schema_id = reader.Get<uint16_t>("a channel's schema_id");
    RecordingTopic topic;
    topic.name = String(reader, "a channel's topic");
    topic.encoding = String(reader, "a channel's message_encoding");
    if (schema_id != 0) {
      const auto schema = schemas_.find(schema_id);
      if (schema == schemas_.end()) {
        Fail(bytes, record.offset, "channel " + topic.name + " names schema " +
                                       std::to_string(schema_id) + ", which no Schema record precedes");
      }
      topic.type = schema->second.name;
      topic.definition = schema->second.data;
    }
    if (!channels_.count(id)) channels_[id] = std::move(topic);
  }

  void ReadSummary(uint64_t summary_start, uint64_t footer, uint32_t summary_crc) {
    if (summary_start < kMagicSize || summary_start > footer) {
      Fail(bytes_, footer, "the footer's summary_start " + std::to_string(summary_start) +
                               " lies outside the file's records");
    }
    if (summary_crc != 0) {
      const uLong crc = crc32(crc32(0L, Z_NULL, 0), bytes_.data + summary_start,
                              static_cast<uInt>(footer + 1 + 8 + 16 - summary_start));
      if (crc != summary_crc) {
        Fail(bytes_, summary_start, "the summary section's CRC does not match its footer's");
      }
    }
    Reader reader(bytes_, summary_start, footer);
    while (reader.left() > 0) {
      const Record record = NextRecord(reader);
      if (record.op == kSchema) ReadSchema(bytes_, record);
      if (record.op == kChannel) ReadChannel(bytes_, record);
    }
  }

  // The data section's records from after the Header up to Data End (or `end`).
  void ScanData(uint64_t end) {
    Reader reader(bytes_, kMagicSize, end);
    const Record header = NextRecord(reader);
    if (header.op != kHeader) Fail(bytes_, kMagicSize, "the file does not begin with a Header record");
    while (reader.left() > 0) {
      const Record record = NextRecord(reader);
      switch (record.op) {
        case kSchema: ReadSchema(bytes_, record); break;
        case kChannel: ReadChannel(bytes_, record); break;
        case kMessage: items_.push_back({record, {}}); break;
        case kChunk: items_.push_back({record, {}}); break;
        case kMessageIndex:
          if (items_.empty() || items_.back().record.op != kChunk) {
            Fail(bytes_, record.offset, "Message Index record that follows no chunk");
          }
          message_indexes_[items_.size() - 1].push_back(record);
          break;
        case kDataEnd: return;
        case kFooter: Fail(bytes_, record.offset, "Footer record inside the data section");
        default: break;  // attachments, metadata: not messages
      }
    }
  }

  // The chunk's fields; its records' bytes (decompressed into `buffer` when compressed,
  // their CRC checked when the writer computed one).
  Bytes ChunkRecords(const Record& chunk, std::string& buffer) const {
    Reader reader(bytes_, chunk.begin, chunk.end);
    reader.Get<uint64_t>("a chunk's message_start_time");
    reader.Get<uint64_t>("a chunk's message_end_time");
    const uint64_t uncompressed_size = reader.Get<uint64_t>("a chunk's uncompressed_size");
    const uint32_t crc = reader.Get<uint32_t>("a chunk's uncompressed_crc");
    const std::string compression = String(reader, "a chunk's compression");
    const uint64_t records_size = reader.Get<uint64_t>("a chunk's records length");
    const uint64_t records_at = reader.pos();
    const std::string_view records = reader.View(records_size, "a chunk's records");
    Bytes inner;
    if (compression.empty()) {
      if (records_size != uncompressed_size) {
        Fail(bytes_, chunk.offset, "uncompressed chunk of " + std::to_string(records_size) +
                                       " bytes declares " + std::to_string(uncompressed_size));
      }
      inner = Bytes{bytes_.file, bytes_.data + records_at, records_size,
                    bytes_.file_offset + records_at, bytes_.label, {}};
    } else {
      Decompress(compression, records, uncompressed_size, buffer, bytes_, chunk.offset);
      inner = Bytes{nullptr, reinterpret_cast<const uint8_t*>(buffer.data()), buffer.size(), 0,
                    bytes_.label + " (" + compression + " chunk at byte " +
                        std::to_string(bytes_.file_offset + chunk.offset) + ", uncompressed)", {}};
    }
    if (crc != 0) {
      uLong actual = crc32(0L, Z_NULL, 0);
      for (uint64_t done = 0; done < inner.size;) {  // crc32 takes 32-bit lengths
        const uInt step = static_cast<uInt>(std::min<uint64_t>(inner.size - done, 1u << 30));
        actual = crc32(actual, inner.data + done, step);
        done += step;
      }
      if (actual != crc) Fail(bytes_, chunk.offset, "the chunk's CRC does not match its content");
    }
    return inner;
  }

  void CountItem(Item& item, Tally& tally) {
    if (item.record.op == kMessage) {
      Reader reader(bytes_, item.record.begin, item.record.end);
      const uint16_t channel = reader.Get<uint16_t>("a message's channel_id");
      reader.Get<uint32_t>("a message's sequence");
      tally.Count(channel, static_cast<int64_t>(reader.Get<uint64_t>("a message's log_time")));
      return;
    }
    const size_t position = static_cast<size_t>(&item - items_.data());
    const auto indexes = message_indexes_.find(position);
    if (indexes == message_indexes_.end()) return ScanChunk(item, tally);
    for (const Record& record : indexes->second) {
      Reader reader(bytes_, record.begin, record.end);
      const uint16_t channel = reader.Get<uint16_t>("a message index's channel_id");
      const uint32_t length = reader.Get<uint32_t>("a message index's records length");
      if (length % 16 != 0) Fail(bytes_, record.offset, "message index entries are not 16 bytes each");
      Reader entries(bytes_, reader.pos(), reader.pos() + length);
      reader.Skip(length, "a message index's records");
      for (uint32_t i = 0; i < length / 16; ++i) {
        tally.Count(channel, static_cast<int64_t>(entries.Get<uint64_t>("an index entry's log_time")));
        entries.Get<uint64_t>("an index entry's offset");
      }
      if (length > 0) item.channels.insert(channel);
    }
  }

  // A chunk without Message Index records: decompressed and its records read.
  void ScanChunk(Item& item, Tally& tally) {
    std::string buffer;
    const Bytes inner = ChunkRecords(item.record, buffer);
    Reader reader(inner, 0, inner.size);
    while (reader.left() > 0) {
      const Record record = NextRecord(reader);
      if (record.op == kSchema) ReadSchema(inner, record);
      if (record.op == kChannel) ReadChannel(inner, record);
      if (record.op != kMessage) continue;
      Reader fields(inner, record.begin, record.end);
      const uint16_t channel = fields.Get<uint16_t>("a message's channel_id");
      fields.Get<uint32_t>("a message's sequence");
      tally.Count(channel, static_cast<int64_t>(fields.Get<uint64_t>("a message's log_time")));
      item.channels.insert(channel);
    }
  }

  void FindChannelsInChunks() {
    std::string buffer;
    for (const Item& item : items_) {
      if (item.record.op != kChunk) continue;
      const Bytes inner = ChunkRecords(item.record, buffer);
      Reader reader(inner, 0, inner.size);
      while (reader.left() > 0) {
        const Record record = NextRecord(reader);
        if (record.op == kSchema) ReadSchema(inner, record);
        if (record.op == kChannel) ReadChannel(inner, record);
      }
    }
  }

  Bytes bytes_;
  std::map<uint16_t, Schema> schemas_;
  std::map<int64_t, RecordingTopic> channels_;
  std::vector<Item> items_;
  std::map<size_t, std::vector<Record>> message_indexes_;  // by position in items_
  std::map<uint16_t, const RecordingTopic*> topic_of_channel_;
};

}  // namespace

std::unique_ptr<Recording> OpenMcap(Bytes bytes) { return std::make_unique<Mcap>(std::move(bytes)); }

}  // namespace omnirig::storage::recording
