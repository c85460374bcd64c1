#pragma once
// The part of a resumable upload received so far: DATA/datasets/{id}/uploads/{TOTAL}/{name},
// outside the images folder, so no listing or download ever sees a half file. Each chunk is
// appended and fdatasynced before the server answers, so the size it reports survives a crash;
// the part stays across restarts (the client resumes from it) until the last byte arrives and
// the file is renamed into the images folder, or the upload is discarded. The declared total is
// the folder's name: a new upload of the same name with another total starts over.

#include <cstdint>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>

namespace omnirig::storage {

// Thrown when another request is writing the same part (its exclusive lock is held).
class UploadBusy : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// What the server holds of an upload: bytes received and the total declared (none: no part).
struct UploadPartStatus {
  int64_t received_bytes = 0;
  std::optional<int64_t> total_bytes;
};

// The part of `name` under `uploads_dir`, whatever its total (the largest when several).
UploadPartStatus FindUploadPart(const std::filesystem::path& uploads_dir, const std::string& name);
// Removes the parts of `name` (every total but `keep_total` when given). Returns how many.
int RemoveUploadParts(const std::filesystem::path& uploads_dir, const std::string& name,
                      std::optional<int64_t> keep_total = std::nullopt);

// One request's hold on a part: opened (created when missing) and locked (flock, exclusive,
// non-blocking, so that two processes sharing the data folder exclude each other too).
class UploadPartWriter {
 public:
  // Throws UploadBusy when another request holds the part, std::runtime_error on I/O errors.
  UploadPartWriter(const std::filesystem::path& uploads_dir, const std::string& name,
                   int64_t total_bytes);
  ~UploadPartWriter();  // unlocks; removes a part this writer created and left empty
  UploadPartWriter(const UploadPartWriter&) = delete;
  UploadPartWriter& operator=(const UploadPartWriter&) = delete;

  int64_t size() const { return size_; }  // bytes in the part (with appended ones)
  void Truncate();                        // to 0 bytes: the upload starts over
  void Append(const char* data, size_t size);
  void Sync();  // writes what is buffered and fdatasyncs: size() is then durable
  // Sync, then renames the part onto `final_path` (creating its folder) and fsyncs both
  // folders. The writer holds nothing afterwards.
  void Publish(const std::filesystem::path& final_path);
  void Remove();  // deletes the part (e.g. its content was refused)
  const std::filesystem::path& path() const { return path_; }

 private:
  void Flush();

  std::filesystem::path path_;
  int fd_ = -1;
  int64_t size_ = 0;
  bool created_ = false;
  std::string buffer_;
};

}  // namespace omnirig::storage
