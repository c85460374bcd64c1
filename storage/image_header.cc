#include "storage/image_header.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <optional>

namespace omnirig::storage {
namespace {

uint32_t ReadBigEndian(std::string_view bytes, size_t offset, int count) {
  uint32_t value = 0;
  for (int i = 0; i < count; ++i) value = (value << 8) | static_cast<uint8_t>(bytes[offset + i]);
  return value;
}

uint32_t ReadLittleEndian(std::string_view bytes, size_t offset, int count) {
  uint32_t value = 0;
  for (int i = count - 1; i >= 0; --i) {
    value = (value << 8) | static_cast<uint8_t>(bytes[offset + i]);
  }
  return value;
}

ImageHeader Corrupt(const std::string& format, const std::string& problem) {
  ImageHeader header;
  header.status = ImageHeader::Status::kCorrupt;
  header.format = format;
  header.problem = problem;
  return header;
}

ImageHeader Accept(const std::string& format, const std::string& content_type, int64_t width,
                   int64_t height) {
  if (width <= 0 || height <= 0 || width > 65535 || height > 65535) {
    return Corrupt(
        format, "implausible image size " + std::to_string(width) + "x" + std::to_string(height));
  }
  ImageHeader header;
  header.status = ImageHeader::Status::kOk;
  header.format = format;
  header.content_type = content_type;
  header.width = static_cast<int>(width);
  header.height = static_cast<int>(height);
  return header;
}

ImageHeader ProbePng(std::string_view head) {
  if (head.size() < 24 || head.substr(12, 4) != "IHDR" || ReadBigEndian(head, 8, 4) != 13) {
    return Corrupt("png", "PNG signature without a complete IHDR chunk");
  }
  return Accept("png", "image/png", ReadBigEndian(head, 16, 4), ReadBigEndian(head, 20, 4));
}

bool IsJpegFrameMarker(uint8_t marker) {
  return marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC;
}

// Walks the JPEG segments up to the first start-of-frame marker, which holds the size.
ImageHeader ProbeJpeg(std::string_view head) {
  size_t offset = 2;
  while (offset + 4 <= head.size()) {
    if (static_cast<uint8_t>(head[offset]) != 0xFF) {
      return Corrupt("jpeg", "JPEG segment does not start with 0xFF");
    }
    const uint8_t marker = static_cast<uint8_t>(head[offset + 1]);
    if (marker == 0xFF) {  // fill byte
      ++offset;
      continue;
    }
    if (marker == 0xD8 || (marker >= 0xD0 && marker <= 0xD7) || marker == 0x01) {
      offset += 2;
      continue;
    }
    if (marker == 0xD9 || marker == 0xDA) break;  // end of image or scan before any frame
    const uint32_t length = ReadBigEndian(head, offset + 2, 2);
    if (length < 2) return Corrupt("jpeg", "JPEG segment with invalid length");
    if (IsJpegFrameMarker(marker)) {
      if (offset + 9 > head.size()) break;
      return Accept("jpeg", "image/jpeg", ReadBigEndian(head, offset + 7, 2),
                    ReadBigEndian(head, offset + 5, 2));
    }
    offset += 2 + length;
  }
  return Corrupt(
      "jpeg", "JPEG without a frame header in its first " + std::to_string(head.size()) + " bytes");
}

ImageHeader ProbeBmp(std::string_view head) {
  if (head.size() < 26) return Corrupt("bmp", "BMP header truncated");
  const int32_t width = static_cast<int32_t>(ReadLittleEndian(head, 18, 4));
  const int32_t height = static_cast<int32_t>(ReadLittleEndian(head, 22, 4));
  return Accept("bmp", "image/bmp", width, height < 0 ? -static_cast<int64_t>(height) : height);
}

// A PNM header: "P5" (or P2, P3, P6), then width, height and maxval separated by whitespace and
// '#' comments. `length` is the offset just past the single whitespace after maxval, where a
// binary PNM's pixels start (0 when `head` ends at maxval). nullopt when a field is missing.
struct PnmHeader {
  int64_t values[3] = {0, 0, 0};  // width, height, maxval
  size_t length = 0;
};

std::optional<PnmHeader> ParsePnmHeader(std::string_view head) {
  PnmHeader header;
  size_t offset = 2;
  for (int64_t& value : header.values) {
    while (offset < head.size()) {
      if (head[offset] == '#') {
        while (offset < head.size() && head[offset] != '\n') ++offset;
      } else if (std::isspace(static_cast<unsigned char>(head[offset]))) {
        ++offset;
      } else {
        break;
      }
    }
    if (offset >= head.size() || !std::isdigit(static_cast<unsigned char>(head[offset]))) {
      return std::nullopt;
    }
    while (offset < head.size() && std::isdigit(static_cast<unsigned char>(head[offset])) &&
           value < 1000000) {
      value = value * 10 + (head[offset++] - '0');
    }
  }
  if (offset < head.size()) header.length = offset + 1;
  return header;
}

ImageHeader ProbePnm(std::string_view head) {
  const std::optional<PnmHeader> header = ParsePnmHeader(head);
  if (!header) return Corrupt("pnm", "PNM header truncated or malformed");
  const int64_t* values = header->values;
  if (values[2] <= 0 || values[2] > 65535) return Corrupt("pnm", "PNM maxval out of range");
  const std::string type =
      head[1] == '5' || head[1] == '2' ? "image/x-portable-graymap" : "image/x-portable-pixmap";
  return Accept("pnm", type, values[0], values[1]);
}

}  // namespace

ImageHeader ProbeImageHeader(std::string_view head) {
  if (head.size() >= 8 && head.substr(0, 8) == std::string_view("\x89PNG\r\n\x1a\n", 8)) {
    return ProbePng(head);
  }
  if (head.size() >= 3 && head.substr(0, 3) == "\xFF\xD8\xFF") return ProbeJpeg(head);
  if (head.size() >= 2 && head.substr(0, 2) == "BM") return ProbeBmp(head);
  if (head.size() >= 3 && head[0] == 'P' &&
      std::string_view("2356").find(head[1]) != std::string_view::npos &&
      std::isspace(static_cast<unsigned char>(head[2]))) {
    return ProbePnm(head);
  }
  ImageHeader header;
  header.problem =
      "not a file omnirig takes: images (PNG, JPEG, BMP, PGM/PPM), videos (.mp4, .m4v, .mov, "
      ".mkv, .webm, .avi), recordings (a ROS 1 .bag, an .mcap, a ROS 2 bag's folder: its "
      "metadata.yaml with its .db3 or .mcap files, or one .tar of it) and .tum trajectories";
  return header;
}

namespace {

const uint32_t* CrcTable() {
  static const auto table = [] {
    std::array<uint32_t, 256> t{};
    for (uint32_t n = 0; n < 256; ++n) {
      uint32_t c = n;
      for (int k = 0; k < 8; ++k) c = (c & 1) ? 0xEDB88320u ^ (c >> 1) : c >> 1;
      t[n] = c;
    }
    return t;
  }();
  return table.data();
}

uint32_t CrcUpdate(uint32_t crc, uint8_t byte) {
  return CrcTable()[(crc ^ byte) & 0xFF] ^ (crc >> 8);
}

std::string Truncated(const std::string& what, uint64_t have, uint64_t need) {
  return what + " is truncated: " + std::to_string(have) + " bytes, the image needs " +
         std::to_string(need);
}

}  // namespace

ImageCompletenessCheck::ImageCompletenessCheck() = default;

void ImageCompletenessCheck::Append(const char* data, size_t size) {
  for (size_t i = 0; i < size; ++i) {
    const uint8_t byte = static_cast<uint8_t>(data[i]);
    ++total_bytes_;
    if (format_ == Format::kUnknown) {
      prefix_.push_back(static_cast<char>(byte));
      if (prefix_.size() < 8) continue;
      const std::string_view p(prefix_);
      if (p == std::string_view("\x89PNG\r\n\x1a\n", 8)) {
        format_ = Format::kPng;
        continue;  // the signature itself
      }
      if (p.substr(0, 3) == "\xFF\xD8\xFF") {
        format_ = Format::kJpeg;
      } else if (p[0] == 'P' && (p[1] == '2' || p[1] == '3')) {
        format_ = Format::kPnmAscii;
        for (size_t k = 2; k < prefix_.size(); ++k) Feed(static_cast<uint8_t>(prefix_[k]));
        continue;
      } else {
        format_ = Format::kOther;
        continue;
      }
      for (char c : prefix_) Feed(static_cast<uint8_t>(c));
      continue;
    }
    if (!problem_.empty() || (done_ && format_ != Format::kPnmAscii)) continue;
    Feed(byte);
  }
}

void ImageCompletenessCheck::Feed(uint8_t byte) {
  switch (format_) {
    case Format::kPng:
      FeedPng(byte);
      break;
    case Format::kJpeg:
      FeedJpeg(byte);
      break;
    case Format::kPnmAscii:
      FeedPnmAscii(byte);
      break;
    default:
      break;
  }
}

void ImageCompletenessCheck::FeedPng(uint8_t byte) {
  if (chunk_pos_ == 0) {
    chunk_length_ = 0;
    chunk_type_.clear();
    crc_ = 0xFFFFFFFFu;
    stored_crc_ = 0;
  }
  if (chunk_pos_ < 4) {
    chunk_length_ = (chunk_length_ << 8) | byte;
  } else if (chunk_pos_ < 8) {
    chunk_type_.push_back(static_cast<char>(byte));
    crc_ = CrcUpdate(crc_, byte);
    if (chunk_pos_ == 7 && chunk_length_ > 0x7FFFFFFFu) {
      problem_ = "PNG chunk " + chunk_type_ + " has an invalid length (the file is corrupt)";
      return;
    }
  } else if (chunk_pos_ < 8 + static_cast<uint64_t>(chunk_length_)) {
    crc_ = CrcUpdate(crc_, byte);
  } else {
    stored_crc_ = (stored_crc_ << 8) | byte;
  }
  ++chunk_pos_;
  if (chunk_pos_ < 12 + static_cast<uint64_t>(chunk_length_)) return;
  png_offset_ += chunk_pos_;
  chunk_pos_ = 0;
  if ((crc_ ^ 0xFFFFFFFFu) != stored_crc_) {
    problem_ = "PNG chunk " + chunk_type_ + " ending at byte " + std::to_string(png_offset_) +
               " fails its CRC check (the file is corrupt)";
    return;
  }
  if (chunk_type_ == "IEND") done_ = true;
}

// States: 0 a marker's 0xFF expected, 1 its code, 2 and 3 a segment's length, 4 inside a
// segment, 5 entropy-coded data, 6 an 0xFF in it.
void ImageCompletenessCheck::FeedJpeg(uint8_t byte) {
  auto marker = [&](uint8_t code) {
    if (code == 0xFF) {
      jpeg_state_ = 1;  // fill byte
    } else if (code == 0xD8 || (code >= 0xD0 && code <= 0xD7) || code == 0x01) {
      jpeg_state_ = 0;
    } else if (code == 0xD9) {
      done_ = true;
    } else {
      jpeg_marker_ = code;
      jpeg_state_ = 2;
    }
  };
  switch (jpeg_state_) {
    case 0:
      if (byte != 0xFF) problem_ = "a JPEG segment does not start with 0xFF (the file is corrupt)";
      jpeg_state_ = 1;
      break;
    case 1:
      marker(byte);
      break;
    case 2:
      jpeg_remaining_ = static_cast<uint32_t>(byte) << 8;
      jpeg_state_ = 3;
      break;
    case 3:
      jpeg_remaining_ |= byte;
      if (jpeg_remaining_ < 2) {
        problem_ = "a JPEG segment has an invalid length (the file is corrupt)";
        break;
      }
      jpeg_remaining_ -= 2;
      jpeg_state_ = jpeg_remaining_ > 0 ? 4 : (jpeg_marker_ == 0xDA ? 5 : 0);
      break;
    case 4:
      if (--jpeg_remaining_ == 0) jpeg_state_ = jpeg_marker_ == 0xDA ? 5 : 0;
      break;
    case 5:
      if (byte == 0xFF) jpeg_state_ = 6;
      break;
    default:  // 6
      if (byte == 0x00 || (byte >= 0xD0 && byte <= 0xD7)) {
        jpeg_state_ = 5;
      } else if (byte != 0xFF) {
        marker(byte);  // the next segment of a progressive or multi-scan image, or EOI
      }
      break;
  }
}

void ImageCompletenessCheck::FeedPnmAscii(uint8_t byte) {
  if (pnm_in_comment_) {
    pnm_in_comment_ = byte != '\n' && byte != '\r';
    return;
  }
  const bool digit = std::isdigit(byte) != 0;
  if (digit && !pnm_in_number_) ++pnm_numbers_;
  pnm_in_number_ = digit;
  if (byte == '#') pnm_in_comment_ = true;
}

std::string ImageCompletenessCheck::Finish(const ImageHeader& header,
                                           std::string_view head) const {
  if (!problem_.empty()) return problem_;
  const uint64_t pixels = static_cast<uint64_t>(header.width) * header.height;
  switch (format_) {
    case Format::kPng:
      if (done_) return "";
      return "PNG is truncated: " + std::to_string(total_bytes_) +
             " bytes and no IEND chunk (the upload was cut short?)";
    case Format::kJpeg:
      if (done_) return "";
      return "JPEG is truncated: " + std::to_string(total_bytes_) +
             " bytes and no end-of-image marker (the upload was cut short?)";
    case Format::kPnmAscii: {
      const uint64_t channels = head.size() > 1 && head[1] == '3' ? 3 : 1;
      const uint64_t need = 3 + pixels * channels;
      if (pnm_numbers_ >= need) return "";
      return "PNM is truncated: " + std::to_string(pnm_numbers_ - std::min<uint64_t>(3, pnm_numbers_)) +
             " samples, the image needs " + std::to_string(need - 3);
    }
    default:
      break;
  }
  if (header.format == "pnm") {
    // ProbeImageHeader refused a malformed header first; `length` is 0 when `head` ends at maxval.
    const std::optional<PnmHeader> parsed = ParsePnmHeader(head);
    if (!parsed || parsed->length == 0) return "PNM header is malformed";
    const uint64_t channels = head.size() > 1 && head[1] == '6' ? 3 : 1;
    const uint64_t sample_bytes = parsed->values[2] > 255 ? 2 : 1;
    const uint64_t need = parsed->length + pixels * channels * sample_bytes;
    if (total_bytes_ < need) return Truncated("PNM", total_bytes_, need);
  }
  if (header.format == "bmp" && head.size() >= 34) {
    const uint32_t offset = ReadLittleEndian(head, 10, 4);
    const uint32_t bits = ReadLittleEndian(head, 28, 2);
    const uint32_t compression = ReadLittleEndian(head, 30, 4);
    if (compression == 0 || compression == 3) {
      const uint64_t row = (static_cast<uint64_t>(bits) * header.width + 31) / 32 * 4;
      const uint64_t need = offset + row * header.height;
      if (total_bytes_ < need) return Truncated("BMP", total_bytes_, need);
    }
  }
  return "";
}

std::string ContentTypeForName(const std::string& name) {
  const size_t dot = name.rfind('.');
  std::string ext = dot == std::string::npos ? "" : name.substr(dot + 1);
  for (char& c : ext) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  if (ext == "png") return "image/png";
  if (ext == "jpg" || ext == "jpeg") return "image/jpeg";
  if (ext == "bmp") return "image/bmp";
  if (ext == "pgm") return "image/x-portable-graymap";
  if (ext == "ppm") return "image/x-portable-pixmap";
  if (ext == "json") return "application/json";
  if (ext == "txt" || ext == "log") return "text/plain; charset=utf-8";
  if (ext == "csv") return "text/csv";
  if (ext == "ply") return "application/octet-stream";
  if (ext == "yml" || ext == "yaml") return "application/yaml";
  if (ext == "svg") return "image/svg+xml";
  if (ext == "mp4" || ext == "m4v") return "video/mp4";
  if (ext == "mov") return "video/quicktime";
  if (ext == "mkv") return "video/x-matroska";
  if (ext == "webm") return "video/webm";
  if (ext == "avi") return "video/x-msvideo";
  return "application/octet-stream";
}

}  // namespace omnirig::storage
