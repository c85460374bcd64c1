#include "storage/atomic_file.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <system_error>
#include <vector>

#include "storage/records.h"

namespace omnirig::storage {
namespace {

[[noreturn]] void ThrowErrno(const std::string& what, const std::filesystem::path& path) {
  // system_error: its code tells a full disk (IsDiskFull) from other failures.
  throw std::system_error(errno, std::generic_category(), what + " " + path.string());
}

}  // namespace

AtomicFileWriter::AtomicFileWriter(std::filesystem::path final_path)
    : final_path_(std::move(final_path)) {
  std::filesystem::create_directories(final_path_.parent_path());
  temp_path_ =
      final_path_.parent_path() / ("." + final_path_.filename().string() + ".part-" + NewId());
  fd_ = ::open(temp_path_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd_ < 0) ThrowErrno("cannot create", temp_path_);
}

AtomicFileWriter::~AtomicFileWriter() {
  if (fd_ >= 0) ::close(fd_);
  if (!committed_) ::unlink(temp_path_.c_str());
}

void AtomicFileWriter::Append(const char* data, size_t size) {
  constexpr size_t kBufferBytes = 1 << 20;
  hasher_.Update(data, size);
  size_ += static_cast<int64_t>(size);
  if (buffer_.size() + size > kBufferBytes) Flush();
  if (size >= kBufferBytes) {
    buffer_.assign(data, size);
    Flush();
  } else {
    buffer_.append(data, size);
  }
}

void AtomicFileWriter::Flush() {
  const int64_t offset = flushed_;
  WriteAll(fd_, buffer_, temp_path_);
  flushed_ += static_cast<int64_t>(buffer_.size());
#ifdef __linux__
  // Start writing this piece to disk now (without waiting), so the disk works while the rest of
  // the body arrives and Commit()'s fsync has little left to do. Only a hint: fsync still makes
  // the file durable, and a failure here changes nothing.
  if (flushed_ > offset) ::sync_file_range(fd_, offset, flushed_ - offset, SYNC_FILE_RANGE_WRITE);
#endif
  buffer_.clear();
}

FileDigest AtomicFileWriter::Seal() {
  if (fd_ >= 0) {
    Flush();
    if (::fsync(fd_) != 0) ThrowErrno("cannot fsync", temp_path_);
    const int fd = fd_;
    fd_ = -1;
    if (::close(fd) != 0) ThrowErrno("cannot close", temp_path_);
    sha256_ = hasher_.HexDigest();
    std::string().swap(buffer_);  // its 1 MiB, for a batch of sealed files
  }
  return FileDigest{size_, sha256_};
}

FileDigest AtomicFileWriter::Commit(bool sync_folder) {
  const FileDigest digest = Seal();
  if (::rename(temp_path_.c_str(), final_path_.c_str()) != 0) {
    ThrowErrno("cannot rename onto", final_path_);
  }
  committed_ = true;
  if (sync_folder) FsyncPath(final_path_.parent_path());
  return digest;
}

FileDigest WriteFileAtomically(const std::filesystem::path& path, std::string_view content) {
  AtomicFileWriter writer(path);
  writer.Append(content);
  return writer.Commit();
}

FileDigest DigestFile(const std::filesystem::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) ThrowErrno("cannot open", path);
  Sha256 hasher;
  std::vector<char> buffer(1 << 20);
  int64_t size = 0;
  while (true) {
    const ssize_t got = ::read(fd, buffer.data(), buffer.size());
    if (got < 0 && errno == EINTR) continue;
    if (got < 0) {
      ::close(fd);
      ThrowErrno("cannot read", path);
    }
    if (got == 0) break;
    hasher.Update(buffer.data(), static_cast<size_t>(got));
    size += got;
  }
  ::close(fd);
  return FileDigest{size, hasher.HexDigest()};
}

void WriteAll(int fd, std::string_view data, const std::filesystem::path& path) {
  while (!data.empty()) {
    const ssize_t written = ::write(fd, data.data(), data.size());
    if (written < 0 && errno == EINTR) continue;
    if (written < 0) ThrowErrno("cannot write", path);
    data.remove_prefix(static_cast<size_t>(written));
  }
}

void FsyncPath(const std::filesystem::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) ThrowErrno("cannot open", path);
  const int status = ::fsync(fd);
  ::close(fd);
  if (status != 0) ThrowErrno("cannot fsync", path);
}

bool IsTemporaryFileName(const std::string& file_name) {
  return !file_name.empty() && file_name[0] == '.' && file_name.find(".part-") != std::string::npos;
}

}  // namespace omnirig::storage
