#pragma once
// Recordings written at test time by independent writers (testing/recordings/write_all.sh):
// ROS 1 bags by Debian's python3-rosbag, MCAP by npm's @mcap/core, ROS 2 bags with rosbag2's
// SQLite schema. Their content follows the formulas below, which the writers share.
//
//   images_{none,bz2,lz4}.bag  ROS 1: /cam0/image_raw (mono8), /cam1/image_raw (rgb8),
//       /bayer/image_raw (bayer_rggb8), /cam0/image_raw/compressed (png), kFrames each;
//       /note (std_msgs/String), 2 messages
//   cut_short.bag      lz4; a recorder killed before closing the bag, /cam0/image_raw only
//   images_{lz4,zstd}.mcap  CDR: the four image topics above (ROS 2 type names), with summary
//   images_bare.mcap   lz4, no summary, no message indexes
//   ros2_db3/          metadata.yaml + two .db3 files: /cam0/image_raw (mono8), /cam1/image_raw
//                      (rgb8), kFrames each, split 6 + 4
//   ros2_db3.tar       the folder above as one archive; ros2_mcap/: metadata.yaml + an .mcap
//   messages/ENCODING.{ros1,cdr}, messages/compressed_{png,jpeg}.{ros1,cdr}: single messages
//
// Frame i's header stamp is kStartS + i * kPeriodNs; it was received 5 ms later.

#include <cstdint>
#include <filesystem>

namespace omnirig::testing {

constexpr int kRecordingWidth = 32, kRecordingHeight = 24;
constexpr int kRecordingFrames = 10;
constexpr int64_t kRecordingStartS = 1700000000;
constexpr int64_t kRecordingPeriodNs = 50000000;  // 20 Hz
constexpr int64_t kRecordingReceiveDelayNs = 5000000;

// Channel c of pixel (x, y) in the mono and colour images (mono8: c = 0; mono16: (value * 257 + 3) mod 65536).
inline int RecordingChannelValue(int x, int y, int c) { return (x * 7 + y * 13 + c * 50) % 256; }
// The colour scene behind the bayer mosaics and the compressed images: RGB, linear in x and y.
inline int RecordingGradient(int x, int y, int c) {
  return c == 0 ? 4 * x + 40 : c == 1 ? 4 * y + 20 : 128;
}

// Writes the recordings into a temporary folder (once per process; removed at exit) and returns
// it. Throws std::runtime_error when a writer fails.
const std::filesystem::path& TestRecordingsDir();

}  // namespace omnirig::testing
