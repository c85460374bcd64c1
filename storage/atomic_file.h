#pragma once
// Crash-safe files: content goes to a hidden temporary file beside the target, is fsynced, then
// renamed over the target and the folder fsynced. A reader (or a restart after a power cut)
// sees either the old file or the complete new one, never a torn write. Temporary names start
// with '.' and contain ".part-", a pattern user names can never take (see names.h), so the
// start-up consistency check can remove leftovers of interrupted writes.

#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>

#include "storage/sha256.h"

namespace omnirig::storage {

// Size and content hash of a stored file.
struct FileDigest {
  int64_t size = 0;
  std::string sha256;  // lower-case hex
};

class AtomicFileWriter {
 public:
  // Creates the parent folders and the temporary file. Throws std::runtime_error on I/O errors.
  explicit AtomicFileWriter(std::filesystem::path final_path);
  ~AtomicFileWriter();  // removes the temporary file unless Commit() succeeded
  AtomicFileWriter(const AtomicFileWriter&) = delete;
  AtomicFileWriter& operator=(const AtomicFileWriter&) = delete;

  void Append(const char* data, size_t size);
  void Append(std::string_view data) { Append(data.data(), data.size()); }
  int64_t bytes_written() const { return size_; }
  // fsync and close the temporary file, which stays until Commit() or destruction: a batch of
  // finished files holds no descriptors. Returns what was written; no Append() after it.
  FileDigest Seal();
  // Seal() if not done, rename over the final path and, with `sync_folder`, fsync the folder
  // (a batch of renames fsyncs each folder once instead); returns what was written.
  FileDigest Commit(bool sync_folder = true);
  const std::filesystem::path& final_path() const { return final_path_; }
  // Where the content is until Commit() (readable once sealed, e.g. to check it).
  const std::filesystem::path& temp_path() const { return temp_path_; }

 private:
  void Flush();

  std::filesystem::path final_path_, temp_path_;
  std::string buffer_;  // batches small appends (HTTP bodies arrive in 4 KiB pieces)
  int fd_ = -1;
  int64_t size_ = 0;
  int64_t flushed_ = 0;  // bytes handed to the kernel (and queued for writeback)
  Sha256 hasher_;
  std::string sha256_;  // set by Seal()
  bool committed_ = false;
};

FileDigest WriteFileAtomically(const std::filesystem::path& path, std::string_view content);
// Size and SHA-256 of an existing file (reads it once).
FileDigest DigestFile(const std::filesystem::path& path);
// Writes all of `data` to `fd`, across short writes and EINTR; throws std::runtime_error naming
// `path` on failure.
void WriteAll(int fd, std::string_view data, const std::filesystem::path& path);
// fsync of a file or folder by path; throws std::runtime_error on failure.
void FsyncPath(const std::filesystem::path& path);
// True for names of temporary files left by an interrupted AtomicFileWriter.
bool IsTemporaryFileName(const std::string& file_name);

}  // namespace omnirig::storage
