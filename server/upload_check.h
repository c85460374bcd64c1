#pragma once
// The checks of an uploaded file's bytes as they arrive, shared by every upload route (PUT of
// one file, multipart POST, resumable chunks): the first bytes for the header, the whole for
// completeness (storage/image_header.h), without decoding pixels. Videos are checked by their
// container instead (storage/video_container.h).

#include <string>

#include "storage/image_header.h"

namespace omnirig::server {

// The header of an upload named `name` whose first bytes are `head`: an image's
// (storage::ProbeImageHeader), or for NAME.tum, a ground-truth trajectory in TUM format that a
// slam job can evaluate against, and for NAME.yaml / NAME.yml a Kalibr target a board-detecting
// job can name (plain text both; the job parses it and says what is wrong).
storage::ImageHeader ProbeUpload(const std::string& name, const std::string& head);

class ImageCheck {
 public:
  void Append(const char* data, size_t size);

  // After the last byte: the header, or HttpError 415 (not an image) or 422 (a corrupt header,
  // or a file cut short or damaged in transfer, which is refused whole: its header alone looks
  // fine).
  storage::ImageHeader Finish(const std::string& name);

 private:
  std::string head_;
  storage::ImageCompletenessCheck completeness_;
};

}  // namespace omnirig::server
