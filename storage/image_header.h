#pragma once
// Reads an uploaded image's header (format, width, height) without decoding its pixels, so
// uploads are checked on arrival at disk speed. Supported: PNG, JPEG, BMP, binary and ASCII
// PGM/PPM. Anything else is "not an image" (HTTP 415); a known signature with a broken or
// truncated header is "corrupt" (HTTP 422).

#include <cstdint>
#include <string>
#include <string_view>

namespace omnirig::storage {

// Bytes of the file's beginning that ProbeImageHeader needs at most (JPEG's size marker may
// follow large EXIF blocks).
constexpr size_t kImageProbeBytes = 256 * 1024;

struct ImageHeader {
  enum class Status { kOk, kNotAnImage, kCorrupt };
  Status status = Status::kNotAnImage;
  std::string format;        // "png", "jpeg", "bmp", "pnm"
  std::string content_type;  // "image/png", ...
  int width = 0, height = 0;
  std::string problem;  // why it was refused (empty when kOk)
};

// `head` holds the first min(kImageProbeBytes, file size) bytes of the file.
ImageHeader ProbeImageHeader(std::string_view head);

// Content type by file extension, for downloads ("application/octet-stream" when unknown).
std::string ContentTypeForName(const std::string& name);

}  // namespace omnirig::storage
