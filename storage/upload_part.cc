#include "storage/upload_part.h"

#include <fcntl.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <system_error>
#include <vector>

#include "storage/atomic_file.h"

namespace omnirig::storage {
namespace {

namespace fs = std::filesystem;

[[noreturn]] void ThrowErrno(const std::string& what, const fs::path& path) {
  // system_error: its code tells a full disk (IsDiskFull) from other failures.
  throw std::system_error(errno, std::generic_category(), what + " " + path.string());
}

// The totals (folder names) under uploads_dir.
std::vector<int64_t> Totals(const fs::path& uploads_dir) {
  std::vector<int64_t> totals;
  std::error_code error;
  for (auto it = fs::directory_iterator(uploads_dir, error);
       !error && it != fs::directory_iterator(); it.increment(error)) {
    const std::string folder = it->path().filename().string();
    char* end = nullptr;
    const long long total = std::strtoll(folder.c_str(), &end, 10);
    if (!folder.empty() && *end == '\0' && total > 0) totals.push_back(total);
  }
  return totals;
}

fs::path PartPath(const fs::path& uploads_dir, int64_t total, const std::string& name) {
  return uploads_dir / std::to_string(total) / name;
}

}  // namespace

UploadPartStatus FindUploadPart(const fs::path& uploads_dir, const std::string& name) {
  UploadPartStatus status;
  for (const int64_t total : Totals(uploads_dir)) {
    std::error_code error;
    const auto size = fs::file_size(PartPath(uploads_dir, total, name), error);
    if (error || (status.total_bytes && static_cast<int64_t>(size) < status.received_bytes)) {
      continue;
    }
    status.received_bytes = static_cast<int64_t>(size);
    status.total_bytes = total;
  }
  return status;
}

int RemoveUploadParts(const fs::path& uploads_dir, const std::string& name,
                      std::optional<int64_t> keep_total) {
  int removed = 0;
  for (const int64_t total : Totals(uploads_dir)) {
    if (keep_total && total == *keep_total) continue;
    std::error_code ignored;
    removed += fs::remove(PartPath(uploads_dir, total, name), ignored) ? 1 : 0;
  }
  return removed;
}

UploadPartWriter::UploadPartWriter(const fs::path& uploads_dir, const std::string& name,
                                   int64_t total_bytes)
    : path_(PartPath(uploads_dir, total_bytes, name)) {
  fs::create_directories(path_.parent_path());
  fd_ = ::open(path_.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd_ < 0 && errno == ENOENT) {
    fd_ = ::open(path_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
    created_ = fd_ >= 0;
    if (fd_ < 0 && errno == EEXIST) fd_ = ::open(path_.c_str(), O_WRONLY | O_CLOEXEC);
  }
  if (fd_ < 0) ThrowErrno("cannot open", path_);
  if (::flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    ::close(fd_);
    fd_ = -1;
    created_ = false;
    throw UploadBusy("another request is uploading " + name + " right now");
  }
  struct stat stats {};
  if (::fstat(fd_, &stats) != 0) ThrowErrno("cannot stat", path_);
  size_ = stats.st_size;
  if (::lseek(fd_, 0, SEEK_END) < 0) ThrowErrno("cannot seek", path_);
}

UploadPartWriter::~UploadPartWriter() {
  if (fd_ < 0) return;
  try {
    Flush();
  } catch (const std::exception&) {
    // The part keeps what reached it; the client asks for its size before resuming.
  }
  if (created_ && size_ == 0) ::unlink(path_.c_str());
  ::close(fd_);  // releases the lock
}

void UploadPartWriter::Truncate() {
  buffer_.clear();
  if (::ftruncate(fd_, 0) != 0 || ::lseek(fd_, 0, SEEK_SET) < 0)
    ThrowErrno("cannot truncate", path_);
  size_ = 0;
}

void UploadPartWriter::Append(const char* data, size_t size) {
  constexpr size_t kBufferBytes = 1 << 20;
  buffer_.append(data, size);
  size_ += static_cast<int64_t>(size);
  if (buffer_.size() >= kBufferBytes) Flush();
}

void UploadPartWriter::Flush() {
  try {
    WriteAll(fd_, buffer_, path_);
  } catch (const std::runtime_error&) {
    // Whatever was not written is not in the part: report the size the file has.
    struct stat stats {};
    if (::fstat(fd_, &stats) == 0) size_ = stats.st_size;
    buffer_.clear();
    throw;
  }
  buffer_.clear();
}

void UploadPartWriter::Sync() {
  Flush();
  if (::fdatasync(fd_) != 0) ThrowErrno("cannot fsync", path_);
}

void UploadPartWriter::Publish(const fs::path& final_path) {
  Sync();
  fs::create_directories(final_path.parent_path());
  if (::rename(path_.c_str(), final_path.c_str()) != 0)
    ThrowErrno("cannot rename onto", final_path);
  ::close(fd_);
  fd_ = -1;
  FsyncPath(final_path.parent_path());
  FsyncPath(path_.parent_path());
  std::error_code ignored;
  fs::remove(path_.parent_path(), ignored);  // the total's folder, when it is empty now
}

void UploadPartWriter::Remove() {
  ::unlink(path_.c_str());
  buffer_.clear();
  ::close(fd_);
  fd_ = -1;
  std::error_code ignored;
  fs::remove(path_.parent_path(), ignored);
}

}  // namespace omnirig::storage
