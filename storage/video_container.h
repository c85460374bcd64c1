#pragma once
// Checks an uploaded video's container structure, without decoding anything: as far as is cheap
// (headers and declared sizes, read with seeks), that the file is one of the containers the
// engine reads and that it is whole. A recording cut short in transfer, or one whose recorder
// never wrote its index, is refused with what is missing; whether the codec decodes is the job's
// check (engine/slam/video_source.h), since storage decodes nothing.
//
//   MP4 / MOV (ISO base media)  top-level boxes (32-bit size, 64-bit "largesize", 0 = to the
//       end) tile the file exactly up to its end, and a 'moov' box (the index) is among them;
//   Matroska / WebM  the EBML magic, the EBML header's declared size, then a Segment whose
//       declared size (unless "unknown", as live recorders write) fits within the file;
//   AVI  'RIFF' chunks ('AVI ', then OpenDML 'AVIX' continuations) whose declared sizes tile
//       the file up to its end.

#include <filesystem>
#include <string>

namespace omnirig::storage {

// True for names the service stores as videos: .mp4 .m4v .mov .mkv .webm .avi (any case).
bool IsVideoName(const std::string& name);

struct VideoContainer {
  enum class Status { kOk, kNotAVideo, kCorrupt };
  Status status = Status::kNotAVideo;
  std::string format;        // "mp4", "quicktime", "matroska", "webm", "avi"
  std::string content_type;  // "video/mp4", "video/quicktime", "video/x-matroska", ...
  std::string problem;       // why it was refused (empty when kOk)
};

// Reads the container structure of the file at `path` (see above). I/O errors are kCorrupt.
VideoContainer CheckVideoContainer(const std::filesystem::path& path);

}  // namespace omnirig::storage
