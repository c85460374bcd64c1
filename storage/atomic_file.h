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
  // fsync, rename over the final path, fsync the folder; returns what was written.
  FileDigest Commit();

 private:
  void Flush();

  std::filesystem::path final_path_, temp_path_;
  std::string buffer_;  // batches small appends (HTTP bodies arrive in 4 KiB pieces)
  int fd_ = -1;
  int64_t size_ = 0;
  int64_t flushed_ = 0;  // bytes handed to the kernel (and queued for writeback)
  Sha256 hasher_;
  bool committed_ = false;
};

FileDigest WriteFileAtomically(const std::filesystem::path& path, std::string_view content);
// Size and SHA-256 of an existing file (reads it once).
FileDigest DigestFile(const std::filesystem::path& path);
// fsync of a file or folder by path; throws std::runtime_error on failure.
void FsyncPath(const std::filesystem::path& path);
// True for names of temporary files left by an interrupted AtomicFileWriter.
bool IsTemporaryFileName(const std::string& file_name);

}  // namespace omnirig::storage
