#pragma once
// Images from robot recordings' messages: sensor_msgs/Image and sensor_msgs/CompressedImage,
// serialized as ROS 1 writes them (little-endian, packed) or as ROS 2 does (CDR, little-endian,
// fields aligned to their size from the end of the 4-byte encapsulation header). The container
// (storage/recording.h) yields the bytes; this makes them a cv::Mat.
//
//   sensor_msgs/Image: header (ROS 1: u32 seq; both: stamp sec, nanosec; string frame_id),
//       u32 height, u32 width, string encoding, u8 is_bigendian, u32 step, u8[] data.
//       Encodings: mono8 and mono16 (grey, CV_8UC1 / CV_16UC1); rgb8, bgr8, rgba8, bgra8
//       (CV_8UC3, BGR, alpha dropped); bayer_rggb8, bayer_bggr8, bayer_gbrg8, bayer_grbg8
//       (debayered bilinearly to CV_8UC3 BGR; the name gives the colours of the top-left 2x2
//       block, row by row).
//   sensor_msgs/CompressedImage: header, string format ("jpeg", "png", or ROS 2's "rgb8; jpeg
//       compressed bgr8"), u8[] data: decoded by OpenCV to grey or BGR, 8 or 16 bits.
//
// The frame's time is the header's stamp (when the camera took it), not the recording's
// receive time.

#include <opencv2/core.hpp>

#include <cstdint>
#include <string>
#include <string_view>

namespace omnirig::io {

enum class Serialization { kRos1, kCdr };

struct ImageMessage {
  cv::Mat image;  // owns its pixels (never a view into the message)
  int64_t stamp_ns = 0;  // the header's stamp, nanoseconds since the Unix epoch
  std::string frame_id;
  std::string encoding;  // Image's encoding, or CompressedImage's format
};

// True for the types DecodeImageMessage takes: sensor_msgs/Image, sensor_msgs/CompressedImage
// and their ROS 2 names (sensor_msgs/msg/...).
bool IsImageMessageType(std::string_view type);

// Decodes one message of `type` (see IsImageMessageType) serialized as `serialization`
// ("ros1" or "cdr" in recordings: see ParseSerialization). Throws InvalidArgument naming the
// field and byte when the message is cut short or inconsistent (data shorter than
// step * height, a step below the width's bytes), an encoding omnirig does not decode, or
// compressed data OpenCV cannot decode.
ImageMessage DecodeImageMessage(std::string_view type, Serialization serialization,
                                std::string_view data);

// The header's stamp of an image message (nanoseconds since the Unix epoch), read without the
// pixels: what pairing a recording's frames needs of every message. Throws InvalidArgument
// when the message ends inside its header.
int64_t ImageMessageStamp(std::string_view type, Serialization serialization,
                          std::string_view data);

// "ros1" -> kRos1, "cdr" -> kCdr; InvalidArgument otherwise.
Serialization ParseSerialization(std::string_view encoding);

}  // namespace omnirig::io
