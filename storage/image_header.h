#pragma once
// Reads an uploaded image's header (format, width, height) without decoding its pixels, so
// uploads are checked on arrival at disk speed. Supported: PNG, JPEG, BMP, binary and ASCII
// PGM/PPM. Anything else is "not an image" (HTTP 415); a known signature with a broken or
// truncated header is "corrupt" (HTTP 422).

#include <cstddef>
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

// Checks, as an upload's bytes arrive, that the file is complete, without decoding pixels:
//   PNG   every chunk whole with a matching CRC-32, up to the IEND chunk;
//   JPEG  every segment whole, up to the end-of-image marker (EOI) after the entropy-coded
//         data (an EOI inside an APP segment, e.g. of an EXIF thumbnail, does not count);
//   PGM/PPM  binary: the header plus width x height x channels samples; ASCII: that many
//         numbers;
//   BMP   uncompressed: the pixel array's offset plus its rows.
// Bytes after the end (some cameras append a trailer) are allowed. Memory: constant.
class ImageCompletenessCheck {
 public:
  ImageCompletenessCheck();
  void Append(const char* data, size_t size);
  // After the last byte: "" when the file is complete, else what is missing or broken, in words
  // for the user. `header` is ProbeImageHeader's verdict on the same file's first bytes (kOk).
  std::string Finish(const ImageHeader& header, std::string_view head) const;

 private:
  enum class Format { kUnknown, kPng, kJpeg, kPnmAscii, kOther };
  void Feed(uint8_t byte);
  void FeedPng(uint8_t byte);
  void FeedJpeg(uint8_t byte);
  void FeedPnmAscii(uint8_t byte);

  Format format_ = Format::kUnknown;
  std::string prefix_;  // the first bytes, until the format is known
  uint64_t total_bytes_ = 0;
  std::string problem_;  // the first problem found (then the rest is not examined)
  bool done_ = false;    // the end of the image was reached
  // PNG: position in the current chunk's 12 + length bytes, its length, type, running CRC.
  uint64_t png_offset_ = 8;  // after the signature
  uint64_t chunk_pos_ = 0;
  uint32_t chunk_length_ = 0;
  std::string chunk_type_;
  uint32_t crc_ = 0, stored_crc_ = 0;
  // JPEG: the parser's state and counters.
  int jpeg_state_ = 0;
  uint8_t jpeg_marker_ = 0;
  uint32_t jpeg_remaining_ = 0;
  // ASCII PNM: whitespace-separated numbers seen (the header's three included), in a number.
  uint64_t pnm_numbers_ = 0;
  bool pnm_in_number_ = false, pnm_in_comment_ = false;
};

// Content type by file extension, for downloads ("application/octet-stream" when unknown).
std::string ContentTypeForName(const std::string& name);

}  // namespace omnirig::storage
