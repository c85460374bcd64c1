#include "server/upload_check.h"

#include <algorithm>

#include "server/http.h"

namespace omnirig::server {

namespace {

bool EndsWith(const std::string& name, const std::string& suffix) {
  return name.size() > suffix.size() &&
         name.compare(name.size() - suffix.size(), suffix.size(), suffix) == 0;
}

}  // namespace

storage::ImageHeader ProbeUpload(const std::string& name, const std::string& head) {
  // Text files beside the images: .tum trajectories (ground truth), .yaml Kalibr targets.
  const bool tum = EndsWith(name, ".tum");
  if (tum || EndsWith(name, ".yaml") || EndsWith(name, ".yml")) {
    storage::ImageHeader header;
    const bool text = std::all_of(head.begin(), head.end(), [](char c) {
      return c == '\n' || c == '\r' || c == '\t' || (c >= 32 && c < 127);
    });
    header.status =
        text ? storage::ImageHeader::Status::kOk : storage::ImageHeader::Status::kNotAnImage;
    header.format = tum ? "tum" : "yaml";
    header.content_type = tum ? "text/plain" : "application/yaml";
    header.problem = text ? "" : (tum ? "a .tum trajectory must be plain text"
                                      : "a .yaml file must be plain text");
    return header;
  }
  return storage::ProbeImageHeader(head);
}

void ImageCheck::Append(const char* data, size_t size) {
  if (head_.size() < storage::kImageProbeBytes) {
    head_.append(data, std::min(size, storage::kImageProbeBytes - head_.size()));
  }
  completeness_.Append(data, size);
}

storage::ImageHeader ImageCheck::Finish(const std::string& name) {
  const storage::ImageHeader header = ProbeUpload(name, head_);
  if (header.status == storage::ImageHeader::Status::kNotAnImage) {
    throw HttpError(415, "unsupported_media_type", name + ": " + header.problem,
                    {{"name", name}});
  }
  std::string problem =
      header.status == storage::ImageHeader::Status::kCorrupt ? header.problem : "";
  const bool text = header.format == "tum" || header.format == "yaml";
  if (problem.empty() && !text) problem = completeness_.Finish(header, head_);
  if (!problem.empty()) {
    throw HttpError(422, "corrupt_image", name + ": " + problem, {{"name", name}});
  }
  std::string().swap(head_);  // a batch holds many sealed uploads
  return header;
}

}  // namespace omnirig::server
