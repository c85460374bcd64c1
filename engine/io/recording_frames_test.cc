#include "engine/io/recording_frames.h"

#include <gtest/gtest.h>

#include <cstring>

#include "engine/util/check.h"

namespace omnirig::io {
namespace {

// A sensor_msgs/Image (mono8, 4x2) as ROS 1 serializes it, every pixel `value`.
std::string Mono8Message(int64_t stamp_ns, uint8_t value) {
  std::string bytes;
  const auto u32 = [&](uint32_t v) { bytes.append(reinterpret_cast<const char*>(&v), 4); };
  const auto text = [&](const std::string& s) {
    u32(static_cast<uint32_t>(s.size()));
    bytes += s;
  };
  u32(0);                                               // seq
  u32(static_cast<uint32_t>(stamp_ns / 1000000000));    // stamp.sec
  u32(static_cast<uint32_t>(stamp_ns % 1000000000));    // stamp.nsec
  text("cam");
  u32(2);  // height
  u32(4);  // width
  text("mono8");
  bytes += '\0';  // is_bigendian
  u32(4);         // step
  text(std::string(8, static_cast<char>(value)));
  return bytes;
}

// Messages held in memory, in the order given (a recording's stored order).
class MemorySource : public MessageSource {
 public:
  MemorySource() {
    topics_ = {{"/cam0", "sensor_msgs/Image", "ros1", 0},
               {"/cam1", "sensor_msgs/Image", "ros1", 0},
               {"/imu", "sensor_msgs/Imu", "ros1", 0}};
  }
  void Add(int topic, std::string bytes) {
    messages_.push_back({topic, std::move(bytes)});
    ++topics_[topic].message_count;
  }
  const std::string& name() const override { return name_; }
  const std::vector<RecordedTopic>& topics() const override { return topics_; }
  void ReadMessages(const std::set<std::string>& topics,
                    const std::function<bool(const RecordedMessage&)>& on_message) const override {
    ++num_reads;
    for (const auto& [topic, bytes] : messages_) {
      if (!topics.count(topics_[topic].name)) continue;
      if (!on_message({&topics_[topic], bytes})) return;
    }
  }
  mutable int num_reads = 0;

 private:
  std::string name_ = "run.bag";
  std::vector<RecordedTopic> topics_;
  std::vector<std::pair<int, std::string>> messages_;
};

constexpr int64_t kStart = 1700000000000000000;
constexpr int64_t kPeriod = 50000000;  // 20 Hz

// Ten frames; cam1 stamped 2 ms after cam0, its frame 4 dropped, and a stray cam1 frame half a
// period after cam0's frame 7 (no partner); cam1's messages stored one frame late.
std::shared_ptr<MemorySource> Recording() {
  auto source = std::make_shared<MemorySource>();
  for (int i = 0; i < 10; ++i) {
    source->Add(0, Mono8Message(kStart + i * kPeriod, static_cast<uint8_t>(i)));
    if (i > 0 && i - 1 != 4) {
      source->Add(1, Mono8Message(kStart + (i - 1) * kPeriod + 2000000, static_cast<uint8_t>(100 + i - 1)));
    }
    if (i == 7) source->Add(1, Mono8Message(kStart + 7 * kPeriod + kPeriod / 2, 250));
    source->Add(2, "imu");
  }
  source->Add(1, Mono8Message(kStart + 9 * kPeriod + 2000000, 109));
  return source;
}

TEST(RecordingFrames, PairsByStampLeavingOutFramesWithoutAPartner) {
  const auto source = Recording();
  const RecordingFrames frames =
      SelectRecordingFrames(*source, {"/cam0", "/cam1"}, RecordingFrameOptions());
  EXPECT_NEAR(frames.pair_tolerance_s, 0.25 * 0.05, 1e-12);  // a quarter of the period
  ASSERT_EQ(frames.frames.size(), 9u);                      // frame 4 has no partner
  EXPECT_EQ(frames.num_unpaired, (std::vector<int64_t>{1, 1}));
  EXPECT_EQ(frames.frames[4].name, "t1700000000.250");
  EXPECT_EQ(frames.frames[4].message, (std::vector<int64_t>{5, 4}));
  RecordingFrameReader reader(source, frames);
  for (int k = 0; k < 9; ++k) {
    const std::vector<cv::Mat> images = reader.Load(k);
    const int i = k < 4 ? k : k + 1;
    ASSERT_EQ(images.size(), 2u);
    EXPECT_EQ(images[0].at<uint8_t>(1, 3), i);
    EXPECT_EQ(images[1].at<uint8_t>(1, 3), 100 + i) << "cam1 of frame " << i;
  }
}

TEST(RecordingFrames, TimeRangeAndStepSelectFrames) {
  const auto source = Recording();
  RecordingFrameOptions options;
  options.start_s = 0.1;
  options.end_s = 0.4;
  options.frame_step = 2;
  const RecordingFrames frames = SelectRecordingFrames(*source, {"/cam0"}, options);
  ASSERT_EQ(frames.frames.size(), 4u);  // 0.10, 0.20, 0.30, 0.40 of 0.10 ... 0.40 every second
  EXPECT_EQ(frames.frames[0].name, "t1700000000.100");
  EXPECT_EQ(frames.frames[1].name, "t1700000000.200");
  options.frame_step = 1;
  options.start_s = 5;
  options.end_s = 6;
  EXPECT_THROW(SelectRecordingFrames(*source, {"/cam0"}, options), InvalidArgument);
}

TEST(RecordingFrames, AnEarlierFrameReadsTheRecordingAgain) {
  const auto source = Recording();
  const RecordingFrames frames = SelectRecordingFrames(*source, {"/cam0"}, RecordingFrameOptions());
  RecordingFrameReader reader(source, frames);
  const int reads_before = source->num_reads;
  EXPECT_EQ(reader.Load(6)[0].at<uint8_t>(0, 0), 6);
  EXPECT_EQ(reader.Load(8)[0].at<uint8_t>(0, 0), 8);
  EXPECT_EQ(source->num_reads, reads_before + 1);
  EXPECT_EQ(reader.Load(2)[0].at<uint8_t>(0, 0), 2);
  EXPECT_EQ(source->num_reads, reads_before + 2);
}

TEST(RecordingFrames, RefusesTopicsThatHoldNoImages) {
  const auto source = Recording();
  try {
    SelectRecordingFrames(*source, {"/imu"}, RecordingFrameOptions());
    FAIL();
  } catch (const InvalidArgument& e) {
    EXPECT_STREQ(e.what(),
                 "topic /imu of recording run.bag holds sensor_msgs/Imu messages, not images "
                 "(sensor_msgs/Image or CompressedImage): its image topics are /cam0, /cam1");
  }
  EXPECT_THROW(SelectRecordingFrames(*source, {"/cam2"}, RecordingFrameOptions()), InvalidArgument);
}

TEST(RecordingFrames, ADamagedMessageFailsTheLoadWithItsReason) {
  auto source = std::make_shared<MemorySource>();
  source->Add(0, Mono8Message(kStart, 1));
  std::string cut = Mono8Message(kStart + kPeriod, 2);
  cut.resize(cut.size() - 3);  // the pixels end early
  source->Add(0, cut);
  const RecordingFrames frames = SelectRecordingFrames(*source, {"/cam0"}, RecordingFrameOptions());
  RecordingFrameReader reader(source, frames);
  EXPECT_EQ(reader.Load(0)[0].at<uint8_t>(0, 0), 1);
  EXPECT_THROW(reader.Load(1), InvalidArgument);
}

}  // namespace
}  // namespace omnirig::io
