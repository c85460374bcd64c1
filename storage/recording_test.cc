#include "storage/recording.h"

#include <gtest/gtest.h>

#include <cstring>
#include <fstream>
#include <map>

#include "testing/storage/test_util.h"
#include "testing/recordings/test_recordings.h"

namespace omnirig::storage {
namespace {

namespace fs = std::filesystem;
using omnirig::testing::kRecordingFrames;
using omnirig::testing::kRecordingPeriodNs;
using omnirig::testing::kRecordingReceiveDelayNs;
using omnirig::testing::kRecordingStartS;
using omnirig::testing::TestRecordingsDir;

fs::path Written(const std::string& name) { return TestRecordingsDir() / name; }

int64_t ReceivedNs(int frame) {
  return kRecordingStartS * 1000000000 + frame * kRecordingPeriodNs + kRecordingReceiveDelayNs;
}

std::string ReadAll(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

void WriteAll(const fs::path& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

// The topic's listing as indexed: name, type, count, first and last receive time, rate.
void ExpectTopic(const Recording& recording, const std::string& name, const std::string& type,
                 int count) {
  const RecordingTopic* topic = recording.FindTopic(name);
  ASSERT_NE(topic, nullptr) << name;
  EXPECT_EQ(topic->type, type) << name;
  EXPECT_EQ(topic->message_count, count) << name;
  EXPECT_EQ(topic->first_time_ns, ReceivedNs(0)) << name;
  EXPECT_EQ(topic->last_time_ns, ReceivedNs(count - 1)) << name;
  EXPECT_NEAR(topic->rate_hz(), 1e9 / kRecordingPeriodNs, 1e-6) << name;
}

// Receive times and sizes of the messages read on `topic`.
std::vector<std::pair<int64_t, size_t>> ReadTopic(const Recording& recording,
                                                  const std::string& topic) {
  std::vector<std::pair<int64_t, size_t>> messages;
  recording.ReadMessages({topic}, [&](const RecordingMessage& message) {
    EXPECT_EQ(message.topic->name, topic);
    messages.emplace_back(message.log_time_ns, message.data.size());
    return true;
  });
  return messages;
}

// The serialized mono8 image of ROS 1: header (seq, stamp, frame_id "cam0"), height, width,
// encoding "mono8", is_bigendian, step, then the pixels (u32 length + bytes).
constexpr size_t kRos1Mono8Size = 4 + 8 + 4 + 4 + 4 + 4 + 4 + 5 + 1 + 4 + 4 + 32 * 24;

constexpr size_t kFirstChunk = 13 + 4096 + 8;

class Ros1BagTest : public ::testing::TestWithParam<std::string> {};

TEST_P(Ros1BagTest, ListsTopicsAndReadsMessagesAsPython3RosbagWroteThem) {
  const auto recording = Recording::Open(Written("images_" + GetParam() + ".bag"));
  const RecordingIndex& index = recording->index();
  EXPECT_EQ(index.format, "rosbag1");
  EXPECT_FALSE(index.cut_short);
  ASSERT_EQ(index.topics.size(), 5u);
  ExpectTopic(*recording, "/cam0/image_raw", "sensor_msgs/Image", kRecordingFrames);
  ExpectTopic(*recording, "/cam1/image_raw", "sensor_msgs/Image", kRecordingFrames);
  ExpectTopic(*recording, "/bayer/image_raw", "sensor_msgs/Image", kRecordingFrames);
  ExpectTopic(*recording, "/cam0/image_raw/compressed", "sensor_msgs/CompressedImage",
              kRecordingFrames);
  const RecordingTopic* note = recording->FindTopic("/note");
  ASSERT_NE(note, nullptr);
  EXPECT_EQ(note->message_count, 2);
  EXPECT_EQ(index.message_count, 4 * kRecordingFrames + 2);
  const RecordingTopic* cam0 = recording->FindTopic("/cam0/image_raw");
  EXPECT_EQ(cam0->encoding, "ros1");
  EXPECT_EQ(cam0->type_hash, "060021388200f6f0f447d0fcd9c64743");  // sensor_msgs/Image's md5sum
  EXPECT_NE(cam0->definition.find("uint8[] data"), std::string::npos);

  const auto messages = ReadTopic(*recording, "/cam0/image_raw");
  ASSERT_EQ(messages.size(), static_cast<size_t>(kRecordingFrames));
  for (int i = 0; i < kRecordingFrames; ++i) {
    EXPECT_EQ(messages[i].first, ReceivedNs(i));
    EXPECT_EQ(messages[i].second, kRos1Mono8Size);
  }
  int total = 0;
  recording->ReadMessages({}, [&](const RecordingMessage&) { return ++total, true; });
  EXPECT_EQ(total, 4 * kRecordingFrames + 2);
  int until_stop = 0;
  recording->ReadMessages({}, [&](const RecordingMessage&) { return ++until_stop < 3; });
  EXPECT_EQ(until_stop, 3);
  EXPECT_THROW(recording->ReadMessages({"/nope"}, [](const RecordingMessage&) { return true; }),
               std::invalid_argument);
}

INSTANTIATE_TEST_SUITE_P(Compressions, Ros1BagTest, ::testing::Values("none", "bz2", "lz4"));

TEST(Ros1Bag, KilledRecorderIsReadUpToTheCutAndSaysSo) {
  const auto recording = Recording::Open(Written("cut_short.bag"));
  const RecordingIndex& index = recording->index();
  EXPECT_TRUE(index.cut_short);
  EXPECT_NE(index.note.find("no index"), std::string::npos) << index.note;
  const RecordingTopic* cam0 = recording->FindTopic("/cam0/image_raw");
  ASSERT_NE(cam0, nullptr);
  // The recorder's unfinished chunk is lost; its whole chunks are read.
  EXPECT_GT(cam0->message_count, 0);
  EXPECT_LT(cam0->message_count, kRecordingFrames);
  const auto messages = ReadTopic(*recording, "/cam0/image_raw");
  ASSERT_EQ(static_cast<int64_t>(messages.size()), cam0->message_count);
  for (size_t i = 0; i < messages.size(); ++i) EXPECT_EQ(messages[i].first, ReceivedNs(i));
}

// A bag cut in transfer (its header names an index past the end) is refused, saying where.
TEST(Ros1Bag, TruncatedClosedBagIsRefusedWithWhere) {
  testing::TempDir temp;
  const std::string bytes = ReadAll(Written("images_lz4.bag"));
  WriteAll(temp.path() / "cut.bag", bytes.substr(0, bytes.size() / 2));
  try {
    Recording::Open(temp.path() / "cut.bag");
    FAIL() << "a truncated bag was read";
  } catch (const RecordingError& e) {
    EXPECT_NE(std::string(e.what()).find("cut.bag: byte " + std::to_string(bytes.size() / 2)),
              std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("cut short"), std::string::npos) << e.what();
  }
}

TEST(Ros1Bag, DamagedChunkIsRefusedWhenRead) {
  testing::TempDir temp;
  std::string bytes = ReadAll(Written("images_bz2.bag"));
  // Inside the first chunk's compressed data (the chunk record begins at byte 4117, after the
  // magic and the bag header record: 4096 bytes of header and padding, two length fields).
  for (size_t i = kFirstChunk + 200; i < kFirstChunk + 260; ++i) bytes[i] = static_cast<char>(0x5a);
  WriteAll(temp.path() / "damaged.bag", bytes);
  const auto recording = Recording::Open(temp.path() / "damaged.bag");  // the index is intact
  try {
    recording->ReadMessages({}, [](const RecordingMessage&) { return true; });
    FAIL() << "a damaged chunk was read";
  } catch (const RecordingError& e) {
    EXPECT_NE(std::string(e.what()).find("bz2 chunk"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("byte 4117"), std::string::npos) << e.what();
  }
}

TEST(Ros1Bag, DamagedRecordStructureIsRefusedWithWhere) {
  testing::TempDir temp;
  std::string bytes = ReadAll(Written("images_none.bag"));
  const uint32_t huge = 0x7fffffff;
  std::memcpy(&bytes[kFirstChunk], &huge, 4);  // the first chunk's header length
  WriteAll(temp.path() / "damaged.bag", bytes);
  try {
    Recording::Open(temp.path() / "damaged.bag");
    FAIL() << "a damaged bag was read";
  } catch (const RecordingError& e) {
    EXPECT_NE(std::string(e.what()).find("damaged.bag: byte 4121: a record's header needs"),
              std::string::npos)
        << e.what();
  }
}

class McapTest : public ::testing::TestWithParam<std::string> {};

TEST_P(McapTest, ListsTopicsAndReadsMessagesAsMcapCoreWroteThem) {
  const auto recording = Recording::Open(Written(GetParam()));
  const RecordingIndex& index = recording->index();
  EXPECT_EQ(index.format, "mcap");
  ASSERT_EQ(index.topics.size(), 4u);
  ExpectTopic(*recording, "/cam0/image_raw", "sensor_msgs/msg/Image", kRecordingFrames);
  ExpectTopic(*recording, "/cam1/image_raw", "sensor_msgs/msg/Image", kRecordingFrames);
  ExpectTopic(*recording, "/bayer/image_raw", "sensor_msgs/msg/Image", kRecordingFrames);
  ExpectTopic(*recording, "/cam0/image_raw/compressed", "sensor_msgs/msg/CompressedImage",
              kRecordingFrames);
  EXPECT_EQ(recording->FindTopic("/cam0/image_raw")->encoding, "cdr");
  const auto messages = ReadTopic(*recording, "/cam1/image_raw");
  ASSERT_EQ(messages.size(), static_cast<size_t>(kRecordingFrames));
  // CDR: encapsulation (4), stamp (8), "cam0" (4 + 5, padded to 4), height, width, "rgb8"
  // (4 + 5), is_bigendian (1, padded), step, then the pixels (4 + 32 * 24 * 3).
  const std::string expected = ReadAll(Written("messages/rgb8.cdr"));
  for (int i = 0; i < kRecordingFrames; ++i) {
    EXPECT_EQ(messages[i].first, ReceivedNs(i));
    EXPECT_EQ(messages[i].second, expected.size());
  }
}

INSTANTIATE_TEST_SUITE_P(Writers, McapTest,
                         ::testing::Values("images_lz4.mcap", "images_zstd.mcap",
                                           "images_bare.mcap"));

TEST(Mcap, TruncatedFileIsRefusedWithWhere) {
  testing::TempDir temp;
  const std::string bytes = ReadAll(Written("images_zstd.mcap"));
  WriteAll(temp.path() / "cut.mcap", bytes.substr(0, 5000));
  try {
    Recording::Open(temp.path() / "cut.mcap");
    FAIL() << "a truncated MCAP file was read";
  } catch (const RecordingError& e) {
    EXPECT_NE(std::string(e.what()).find("cut.mcap: byte 5000: the file does not end with MCAP's "
                                         "closing magic"),
              std::string::npos)
        << e.what();
  }
}

TEST(Mcap, DamagedChunkFailsItsCrc) {
  testing::TempDir temp;
  std::string bytes = ReadAll(Written("images_bare.mcap"));
  // The bare file has no message indexes: indexing decompresses every chunk, checking its CRC.
  const size_t chunk = bytes.find('\x06', 8 + 9 + 4 + 5);
  ASSERT_NE(chunk, std::string::npos);
  bytes[bytes.size() / 2] = static_cast<char>(bytes[bytes.size() / 2] ^ 0x01);
  WriteAll(temp.path() / "damaged.mcap", bytes);
  try {
    Recording::Open(temp.path() / "damaged.mcap");
    FAIL() << "a damaged MCAP file was read";
  } catch (const RecordingError& e) {
    EXPECT_NE(std::string(e.what()).find("damaged.mcap"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("chunk"), std::string::npos) << e.what();
  }
}

TEST(Ros2Bag, FolderOfDb3FilesIsOneRecording) {
  for (const std::string name : {"ros2_db3", "ros2_db3/metadata.yaml", "ros2_db3.tar"}) {
    SCOPED_TRACE(name);
    const auto recording = Recording::Open(Written(name));
    EXPECT_EQ(recording->index().format, "rosbag2");
    EXPECT_EQ(recording->index().storage, "sqlite3");
    ASSERT_EQ(recording->index().topics.size(), 2u);
    ExpectTopic(*recording, "/cam0/image_raw", "sensor_msgs/msg/Image", kRecordingFrames);
    ExpectTopic(*recording, "/cam1/image_raw", "sensor_msgs/msg/Image", kRecordingFrames);
    const auto messages = ReadTopic(*recording, "/cam0/image_raw");
    ASSERT_EQ(messages.size(), static_cast<size_t>(kRecordingFrames));
    const std::string expected = ReadAll(Written("messages/mono8.cdr"));
    for (int i = 0; i < kRecordingFrames; ++i) {
      EXPECT_EQ(messages[i].first, ReceivedNs(i));
      EXPECT_EQ(messages[i].second, expected.size());
    }
  }
}

TEST(Ros2Bag, FolderOfMcapFiles) {
  const auto recording = Recording::Open(Written("ros2_mcap"));
  EXPECT_EQ(recording->index().storage, "mcap");
  ExpectTopic(*recording, "/cam0/image_raw", "sensor_msgs/msg/Image", kRecordingFrames);
}

TEST(Ros2Bag, MissingOrDamagedFilesAreRefusedByName) {
  testing::TempDir temp;
  fs::copy(Written("ros2_db3"), temp.path() / "bag");
  fs::remove(temp.path() / "bag" / "ros2_db3_1.db3");
  try {
    Recording::Open(temp.path() / "bag");
    FAIL();
  } catch (const RecordingError& e) {
    EXPECT_NE(std::string(e.what()).find("metadata.yaml lists ros2_db3_1.db3"), std::string::npos)
        << e.what();
  }
  const std::string db3 = ReadAll(Written("ros2_db3/ros2_db3_1.db3"));
  WriteAll(temp.path() / "bag" / "ros2_db3_1.db3", db3.substr(0, db3.size() - 8192));
  try {
    Recording::Open(temp.path() / "bag");
    FAIL();
  } catch (const RecordingError& e) {
    EXPECT_NE(std::string(e.what()).find("ros2_db3_1.db3"), std::string::npos) << e.what();
  }
  const std::string tar = ReadAll(Written("ros2_db3.tar"));
  WriteAll(temp.path() / "cut.tar", tar.substr(0, 3000));
  try {
    Recording::Open(temp.path() / "cut.tar");
    FAIL();
  } catch (const RecordingError& e) {
    EXPECT_NE(std::string(e.what()).find("cut.tar: byte"), std::string::npos) << e.what();
  }
}

TEST(Recording, OtherFilesAreRefusedSayingWhatIsRead) {
  testing::TempDir temp;
  WriteAll(temp.path() / "notes.bag", "hello, not a bag");
  try {
    Recording::Open(temp.path() / "notes.bag");
    FAIL();
  } catch (const RecordingError& e) {
    EXPECT_NE(std::string(e.what()).find("#ROSBAG V2.0"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(IsRecordingName("run.BAG"));
  EXPECT_TRUE(IsRecordingName("run/metadata.yaml"));
  EXPECT_TRUE(IsRecordingName("run/run_0.db3"));
  EXPECT_TRUE(IsRecordingName("run.mcap"));
  EXPECT_TRUE(IsRecordingName("run.tar"));
  EXPECT_FALSE(IsRecordingName("run.png"));
  EXPECT_FALSE(IsRecordingName("settings.yaml"));
}

}  // namespace
}  // namespace omnirig::storage
