#include "storage/video_container.h"

#include <algorithm>
#include <cctype>
#include <cstdint>
#include <fstream>
#include <set>

namespace omnirig::storage {
namespace {

namespace fs = std::filesystem;
using Status = VideoContainer::Status;

std::string Lower(std::string text) {
  for (char& c : text) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

uint64_t BigEndian(const unsigned char* bytes, int count) {
  uint64_t value = 0;
  for (int i = 0; i < count; ++i) value = (value << 8) | bytes[i];
  return value;
}

uint32_t LittleEndian32(const unsigned char* bytes) {
  return bytes[0] | (bytes[1] << 8) | (bytes[2] << 16) | (static_cast<uint32_t>(bytes[3]) << 24);
}

// Reads `count` bytes at `offset`; false when the file ends first.
bool ReadAt(std::ifstream& in, uint64_t offset, unsigned char* bytes, int count) {
  in.clear();
  in.seekg(static_cast<std::streamoff>(offset));
  in.read(reinterpret_cast<char*>(bytes), count);
  return in.gcount() == count;
}

VideoContainer Result(Status status, const std::string& format, const std::string& content_type,
                      const std::string& problem = "") {
  return {status, format, content_type, problem};
}

VideoContainer CheckIsoBoxes(std::ifstream& in, uint64_t file_size) {
  unsigned char head[16];
  ReadAt(in, 0, head, 12);
  const bool quicktime = std::string(reinterpret_cast<char*>(head + 4), 4) == "ftyp" &&
                         std::string(reinterpret_cast<char*>(head + 8), 4) == "qt  ";
  const std::string format = quicktime ? "quicktime" : "mp4";
  const std::string type_name = quicktime ? "video/quicktime" : "video/mp4";
  const auto corrupt = [&](const std::string& problem) {
    return Result(Status::kCorrupt, format, type_name, problem);
  };
  bool has_moov = false;
  for (uint64_t pos = 0; pos < file_size;) {
    if (file_size - pos < 8 || !ReadAt(in, pos, head, 8)) {
      return corrupt("the file ends inside a box header at byte " + std::to_string(pos));
    }
    const std::string type(reinterpret_cast<char*>(head + 4), 4);
    if (!std::all_of(type.begin(), type.end(), [](char c) { return c >= 32 && c < 127; })) {
      return corrupt("no box starts at byte " + std::to_string(pos) + " (damaged or not MP4)");
    }
    uint64_t size = BigEndian(head, 4), header = 8;
    if (size == 1) {
      if (!ReadAt(in, pos + 8, head + 8, 8))
        return corrupt("the file ends inside box '" + type + "'");
      size = BigEndian(head + 8, 8);
      header = 16;
    } else if (size == 0) {
      size = file_size - pos;
    }
    if (size < header) return corrupt("box '" + type + "' declares an impossible size");
    if (size > file_size - pos) {
      return corrupt("box '" + type + "' at byte " + std::to_string(pos) + " declares " +
                     std::to_string(size) + " bytes but the file ends after " +
                     std::to_string(file_size - pos) + ": the upload is incomplete");
    }
    has_moov = has_moov || type == "moov";
    pos += size;
  }
  if (!has_moov) {
    return corrupt(
        "no 'moov' box (the index a recorder writes when it stops): the recording "
        "was not finished");
  }
  return Result(Status::kOk, format, type_name);
}

// An EBML variable-size integer at `offset`: its value and length; false when malformed.
// `unknown` is set for the reserved all-ones value ("size unknown").
bool ReadVint(std::ifstream& in, uint64_t offset, bool keep_marker, uint64_t& value, int& length,
              bool& unknown) {
  unsigned char bytes[8];
  if (!ReadAt(in, offset, bytes, 1) || bytes[0] == 0) return false;
  length = 1;
  while (!(bytes[0] & (0x80 >> (length - 1)))) ++length;
  if (length > 1 && !ReadAt(in, offset + 1, bytes + 1, length - 1)) return false;
  value = keep_marker ? bytes[0] : (bytes[0] & (0xFF >> length));
  bool all_ones = (bytes[0] & (0xFF >> length)) == (0xFF >> length);
  for (int i = 1; i < length; ++i) {
    value = (value << 8) | bytes[i];
    all_ones = all_ones && bytes[i] == 0xFF;
  }
  unknown = !keep_marker && all_ones;
  return true;
}

VideoContainer CheckMatroska(std::ifstream& in, uint64_t file_size, bool webm) {
  const std::string format = webm ? "webm" : "matroska";
  const std::string type_name = webm ? "video/webm" : "video/x-matroska";
  const auto corrupt = [&](const std::string& problem) {
    return Result(Status::kCorrupt, format, type_name, problem);
  };
  uint64_t size = 0, id = 0;
  int length = 0, id_length = 0;
  bool unknown = false;
  if (!ReadVint(in, 4, false, size, length, unknown) || unknown) {
    return corrupt("the EBML header's size is malformed");
  }
  uint64_t pos = 4 + length + size;
  if (pos >= file_size) return corrupt("the file ends inside the EBML header");
  if (!ReadVint(in, pos, true, id, id_length, unknown) || id != 0x18538067) {
    return corrupt("no Segment follows the EBML header (damaged or not Matroska)");
  }
  if (!ReadVint(in, pos + id_length, false, size, length, unknown)) {
    return corrupt("the Segment's size is malformed");
  }
  const uint64_t data = pos + id_length + length;
  if (!unknown && (data > file_size || size > file_size - data)) {
    return corrupt("the Segment declares " + std::to_string(size) + " bytes but the file holds " +
                   std::to_string(file_size > data ? file_size - data : 0) +
                   " after its header: the upload is incomplete");
  }
  return Result(Status::kOk, format, type_name);
}

VideoContainer CheckAvi(std::ifstream& in, uint64_t file_size) {
  const auto corrupt = [&](const std::string& problem) {
    return Result(Status::kCorrupt, "avi", "video/x-msvideo", problem);
  };
  unsigned char head[12];
  for (uint64_t pos = 0; pos < file_size;) {
    if (file_size - pos < 12 || !ReadAt(in, pos, head, 12)) {
      return corrupt("the file ends inside a RIFF header at byte " + std::to_string(pos));
    }
    const std::string tag(reinterpret_cast<char*>(head), 4);
    const std::string form(reinterpret_cast<char*>(head + 8), 4);
    if (tag != "RIFF" || (form != (pos == 0 ? "AVI " : "AVIX"))) {
      return corrupt("no RIFF 'AVI'/'AVIX' chunk at byte " + std::to_string(pos));
    }
    const uint64_t size = LittleEndian32(head + 4);
    const uint64_t chunk = 8 + size + (size & 1);
    if (chunk > file_size - pos && 8 + size != file_size - pos) {
      return corrupt("the RIFF chunk at byte " + std::to_string(pos) + " declares " +
                     std::to_string(size) + " bytes but the file ends after " +
                     std::to_string(file_size - pos - 8) + ": the upload is incomplete");
    }
    pos += std::min(chunk, file_size - pos);
  }
  return Result(Status::kOk, "avi", "video/x-msvideo");
}

}  // namespace

bool IsVideoName(const std::string& name) {
  static const std::set<std::string> kExtensions = {".mp4", ".m4v",  ".mov",
                                                    ".mkv", ".webm", ".avi"};
  return kExtensions.count(Lower(fs::path(name).extension().string())) > 0;
}

VideoContainer CheckVideoContainer(const fs::path& path) {
  std::error_code error;
  const uint64_t file_size = fs::file_size(path, error);
  std::ifstream in(path, std::ios::binary);
  if (error || !in) return Result(Status::kCorrupt, "", "", "the file cannot be read");
  unsigned char head[12] = {};
  if (file_size < 12 || !ReadAt(in, 0, head, 12)) {
    return Result(Status::kNotAVideo, "", "", "too short to be a video");
  }
  static const std::set<std::string> kIsoBoxes = {"ftyp", "moov", "mdat", "wide",
                                                  "free", "skip", "pnot", "uuid"};
  if (kIsoBoxes.count(std::string(reinterpret_cast<char*>(head + 4), 4))) {
    return CheckIsoBoxes(in, file_size);
  }
  if (BigEndian(head, 4) == 0x1A45DFA3) {
    return CheckMatroska(in, file_size, Lower(path.extension().string()) == ".webm");
  }
  if (std::string(reinterpret_cast<char*>(head), 4) == "RIFF" &&
      std::string(reinterpret_cast<char*>(head + 8), 4) == "AVI ") {
    return CheckAvi(in, file_size);
  }
  return Result(Status::kNotAVideo, "", "",
                "not a video container omnirig reads (MP4/MOV, Matroska/WebM or AVI)");
}

}  // namespace omnirig::storage
