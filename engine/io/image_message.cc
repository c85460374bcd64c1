#include "engine/io/image_message.h"

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <cstring>

#include "engine/util/check.h"

namespace omnirig::io {
namespace {

// Reads the fields of one message in order, ROS 1 (packed) or CDR (aligned) alike; a field that
// does not fit throws, naming it and its byte.
class FieldReader {
 public:
  FieldReader(std::string_view type, Serialization serialization, std::string_view data)
      : type_(type), cdr_(serialization == Serialization::kCdr), data_(data) {
    if (!cdr_) return;
    Need(4, "the CDR encapsulation header");
    const uint8_t kind = static_cast<uint8_t>(data_[1]);
    // CDR_LE (1) and CDR2's little-endian PLAIN_CDR2 (7); the fields of these types align the
    // same in both. Big-endian kinds are even.
    if (data_[0] != 0 || (kind != 1 && kind != 7)) {
      Fail(0, "CDR encapsulation " + std::to_string(static_cast<int>(data_[0])) + "," +
                  std::to_string(kind) + " is not little-endian CDR, which ROS 2 writes");
    }
    pos_ = 4;
  }

  uint32_t U32(const char* field) {
    Align(4);
    Need(4, field);
    uint32_t value;
    std::memcpy(&value, data_.data() + pos_, 4);
    pos_ += 4;
    return value;
  }
  uint8_t U8(const char* field) {
    Need(1, field);
    return static_cast<uint8_t>(data_[pos_++]);
  }
  std::string String(const char* field) {
    const uint32_t size = U32(field);
    Need(size, field);
    std::string text(data_.substr(pos_, size));
    pos_ += size;
    if (cdr_ && !text.empty() && text.back() == '\0') text.pop_back();  // CDR counts the NUL
    return text;
  }
  // A u8[] field: its length, then a view of its bytes.
  std::string_view Bytes(const char* field) {
    const uint32_t size = U32(field);
    Need(size, field);
    const std::string_view bytes = data_.substr(pos_, size);
    pos_ += size;
    return bytes;
  }

  [[noreturn]] void Fail(size_t at, const std::string& problem) const {
    throw InvalidArgument(std::string(type_) + " message: byte " + std::to_string(at) + ": " +
                          problem);
  }

 private:
  void Align(size_t alignment) {
    if (cdr_) pos_ = 4 + (pos_ - 4 + alignment - 1) / alignment * alignment;
  }
  void Need(size_t count, const char* field) const {
    if (pos_ > data_.size() || count > data_.size() - pos_) {
      Fail(pos_, std::string("the message ends inside ") + field + " (" +
                     std::to_string(data_.size()) + " bytes)");
    }
  }

  std::string_view type_;
  bool cdr_;
  std::string_view data_;
  size_t pos_ = 0;
};

// std_msgs/Header: ROS 1 starts with a sequence number, ROS 2 has none.
void ReadHeader(FieldReader& reader, Serialization serialization, ImageMessage& message) {
  if (serialization == Serialization::kRos1) reader.U32("header.seq");
  const uint32_t sec = reader.U32("header.stamp.sec");
  const uint32_t nanosec = reader.U32("header.stamp.nanosec");
  // ROS 2's sec is signed; stamps before 1970 do not occur in recordings.
  message.stamp_ns = static_cast<int64_t>(sec) * 1000000000 + nanosec;
  message.frame_id = reader.String("header.frame_id");
}

struct EncodingLayout {
  const char* name;
  int channels;
  int bytes_per_channel;
  int bayer_to_bgr;  // the cv::cvtColor code for Bayer mosaics, else -1
};

// OpenCV names a Bayer pattern by the second row's second and third pixels, ROS by the
// top-left 2x2 block: ROS's rggb is OpenCV's BG (cv_bridge maps them the same way).
constexpr EncodingLayout kEncodings[] = {
    {"mono8", 1, 1, -1},  {"mono16", 1, 2, -1}, {"rgb8", 3, 1, -1},
    {"bgr8", 3, 1, -1},   {"rgba8", 4, 1, -1},  {"bgra8", 4, 1, -1},
    {"bayer_rggb8", 1, 1, cv::COLOR_BayerBG2BGR}, {"bayer_bggr8", 1, 1, cv::COLOR_BayerRG2BGR},
    {"bayer_gbrg8", 1, 1, cv::COLOR_BayerGR2BGR}, {"bayer_grbg8", 1, 1, cv::COLOR_BayerGB2BGR},
};

const EncodingLayout* FindEncoding(const std::string& name) {
  for (const auto& layout : kEncodings) {
    if (name == layout.name) return &layout;
  }
  return nullptr;
}

// The message's pixels in the layout of `encoding`, as the returned image (BGR or grey).
cv::Mat ConvertPixels(const cv::Mat& raw, const EncodingLayout& layout, bool big_endian) {
  const std::string name = layout.name;
  cv::Mat image;
  if (layout.bayer_to_bgr >= 0) {
    cv::cvtColor(raw, image, layout.bayer_to_bgr);
  } else if (name == "rgb8") {
    cv::cvtColor(raw, image, cv::COLOR_RGB2BGR);
  } else if (name == "rgba8") {
    cv::cvtColor(raw, image, cv::COLOR_RGBA2BGR);
  } else if (name == "bgra8") {
    cv::cvtColor(raw, image, cv::COLOR_BGRA2BGR);
  } else {
    image = raw.clone();
    if (name == "mono16" && big_endian) {
      for (int y = 0; y < image.rows; ++y) {
        auto* row = image.ptr<uint16_t>(y);
        for (int x = 0; x < image.cols; ++x) row[x] = static_cast<uint16_t>((row[x] << 8) | (row[x] >> 8));
      }
    }
  }
  return image;
}

void DecodeRaw(FieldReader& reader, ImageMessage& message) {
  const uint32_t height = reader.U32("height");
  const uint32_t width = reader.U32("width");
  message.encoding = reader.String("encoding");
  const bool big_endian = reader.U8("is_bigendian") != 0;
  const uint32_t step = reader.U32("step");
  const std::string_view data = reader.Bytes("data");
  const EncodingLayout* layout = FindEncoding(message.encoding);
  if (!layout) {
    throw InvalidArgument("sensor_msgs/Image encoding '" + message.encoding +
                          "' is not one omnirig decodes (mono8, mono16, rgb8, bgr8, rgba8, "
                          "bgra8, bayer_rggb8, bayer_bggr8, bayer_gbrg8, bayer_grbg8)");
  }
  const uint64_t row_bytes = uint64_t{width} * layout->channels * layout->bytes_per_channel;
  if (height == 0 || width == 0 || width > 1 << 16 || height > 1 << 16) {
    throw InvalidArgument("sensor_msgs/Image of " + std::to_string(width) + "x" +
                          std::to_string(height) + " pixels: not an image omnirig decodes");
  }
  if (step < row_bytes) {
    throw InvalidArgument("sensor_msgs/Image step " + std::to_string(step) + " is less than a " +
                          std::to_string(width) + "-pixel " + message.encoding + " row (" +
                          std::to_string(row_bytes) + " bytes)");
  }
  if (step % layout->bytes_per_channel != 0) {
    throw InvalidArgument("sensor_msgs/Image step " + std::to_string(step) +
                          " is not a whole number of " + message.encoding + " samples (" +
                          std::to_string(layout->bytes_per_channel) + " bytes each)");
  }
  if (data.size() < uint64_t{step} * height) {
    throw InvalidArgument("sensor_msgs/Image data holds " + std::to_string(data.size()) +
                          " bytes, less than step * height = " +
                          std::to_string(uint64_t{step} * height));
  }
  const int type = CV_MAKETYPE(layout->bytes_per_channel == 2 ? CV_16U : CV_8U, layout->channels);
  // A view of the message's bytes (not written to), converted into an image that owns its pixels.
  const cv::Mat raw(static_cast<int>(height), static_cast<int>(width), type,
                    const_cast<char*>(data.data()), step);
  message.image = ConvertPixels(raw, *layout, big_endian);
}

void DecodeCompressed(FieldReader& reader, ImageMessage& message) {
  message.encoding = reader.String("format");
  const std::string_view data = reader.Bytes("data");
  if (data.empty()) {
    throw InvalidArgument("sensor_msgs/CompressedImage (format '" + message.encoding +
                          "') holds no data");
  }
  const cv::Mat bytes(1, static_cast<int>(data.size()), CV_8UC1, const_cast<char*>(data.data()));
  try {
    message.image = cv::imdecode(bytes, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR);
  } catch (const cv::Exception&) {
    message.image.release();  // refused below as any data that does not decode
  }
  if (message.image.empty()) {
    throw InvalidArgument("sensor_msgs/CompressedImage (format '" + message.encoding + "', " +
                          std::to_string(data.size()) +
                          " bytes) does not decode as JPEG or PNG: damaged or another format");
  }
  if (message.image.channels() == 4) cv::cvtColor(message.image, message.image, cv::COLOR_BGRA2BGR);
}

bool EndsWith(std::string_view text, std::string_view suffix) {
  return text.size() >= suffix.size() && text.substr(text.size() - suffix.size()) == suffix;
}

}  // namespace

bool IsImageMessageType(std::string_view type) {
  return type == "sensor_msgs/Image" || type == "sensor_msgs/msg/Image" ||
         type == "sensor_msgs/CompressedImage" || type == "sensor_msgs/msg/CompressedImage";
}

ImageMessage DecodeImageMessage(std::string_view type, Serialization serialization,
                                std::string_view data) {
  if (!IsImageMessageType(type)) {
    throw InvalidArgument("messages of type " + std::string(type) +
                          " are not images: omnirig decodes sensor_msgs/Image and "
                          "sensor_msgs/CompressedImage");
  }
  FieldReader reader(type, serialization, data);
  ImageMessage message;
  ReadHeader(reader, serialization, message);
  if (EndsWith(type, "CompressedImage")) {
    DecodeCompressed(reader, message);
  } else {
    DecodeRaw(reader, message);
  }
  return message;
}

int64_t ImageMessageStamp(std::string_view type, Serialization serialization,
                          std::string_view data) {
  FieldReader reader(type, serialization, data);
  if (serialization == Serialization::kRos1) reader.U32("header.seq");
  const uint32_t sec = reader.U32("header.stamp.sec");
  const uint32_t nanosec = reader.U32("header.stamp.nanosec");
  return static_cast<int64_t>(sec) * 1000000000 + nanosec;
}

Serialization ParseSerialization(std::string_view encoding) {
  if (encoding == "ros1") return Serialization::kRos1;
  if (encoding == "cdr") return Serialization::kCdr;
  throw InvalidArgument("messages encoded as '" + std::string(encoding) +
                        "' are not read: omnirig reads ROS 1 serialization and CDR (ROS 2)");
}

}  // namespace omnirig::io
