// One image message of a recording (engine/io/image_message.h): the first byte chooses the
// type and serialization (sensor_msgs/Image or CompressedImage, ROS 1 or CDR), the rest is the
// serialized message. Each either decodes to an image of the size it declares or throws
// InvalidArgument naming what is wrong; any other exception or a crash is a failure here.

#include <cstddef>
#include <cstdint>
#include <string_view>

#include "engine/io/image_message.h"
#include "engine/util/check.h"
#include "fuzz/fuzz_check.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace omnirig::io;
  if (size < 1) return 0;
  static const char* const kTypes[] = {"sensor_msgs/Image", "sensor_msgs/CompressedImage",
                                       "sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage"};
  const std::string_view type = kTypes[data[0] & 3];
  const Serialization serialization = (data[0] & 4) ? Serialization::kCdr : Serialization::kRos1;
  const std::string_view message(reinterpret_cast<const char*>(data + 1), size - 1);
  try {
    const ImageMessage decoded = DecodeImageMessage(type, serialization, message);
    FUZZ_CHECK(!decoded.image.empty());
  } catch (const omnirig::InvalidArgument&) {
  }
  return 0;
}
