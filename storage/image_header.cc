#include "storage/image_header.h"

#include <cctype>

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

// PNM: "P5" then whitespace/comment separated width, height, maxval.
ImageHeader ProbePnm(std::string_view head) {
  size_t offset = 2;
  int64_t values[3] = {0, 0, 0};
  for (int64_t& value : values) {
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
      return Corrupt("pnm", "PNM header truncated or malformed");
    }
    while (offset < head.size() && std::isdigit(static_cast<unsigned char>(head[offset])) &&
           value < 1000000) {
      value = value * 10 + (head[offset++] - '0');
    }
  }
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
  header.problem = "not a supported image (PNG, JPEG, BMP, PGM/PPM)";
  return header;
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
  return "application/octet-stream";
}

}  // namespace omnirig::storage
