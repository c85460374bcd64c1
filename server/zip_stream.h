#pragma once
// A zip archive of files on disk, produced piece by piece as it is sent: never held in memory
// nor written to disk. Each file is stored (no compression: a job's bulk is PNG, TIFF and
// binary PLY, which deflate barely shrinks) after a local header whose CRC-32 and sizes are
// left to the data descriptor that follows the data (general purpose flag bit 3), since the
// CRC is known only once the file was read; the central directory ends the archive. Names are
// UTF-8 (flag bit 11). ZIP64 fields (APPNOTE 6.3.10, 4.5.3) are written only where a size or
// an offset does not fit the classic 32-bit fields, so archives below 4 GiB are plain zip.
//
// Each file is checked as it is read against its record: its size and SHA-256. A file that
// changed or vanished since it was recorded stops the archive (Next throws): a client never
// receives a whole-looking archive with content other than the job's.

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "storage/sha256.h"

namespace omnirig::server {

struct ZipEntry {
  std::string name;  // inside the archive ('/'-separated)
  std::filesystem::path path;
  int64_t size = 0;    // bytes, as recorded
  std::string sha256;  // hex, as recorded
};

class ZipStream {
 public:
  // The classic fields' limit; a smaller one only makes tests write ZIP64 on small files.
  static constexpr uint64_t kClassicLimit = 0xFFFFFFFFu;

  explicit ZipStream(std::vector<ZipEntry> entries, uint64_t zip64_from = kClassicLimit);

  // Appends the next piece of the archive (at most ~256 KiB) to `out`; false, appending
  // nothing, once the archive is complete. Throws std::runtime_error when a file cannot be read
  // or differs from its record.
  bool Next(std::string& out);

  // Bytes produced so far.
  uint64_t offset() const { return offset_; }

 private:
  struct Written {
    uint32_t crc32 = 0;
    uint64_t size = 0;
    uint64_t header_offset = 0;
    uint16_t dos_time = 0, dos_date = 0;
  };
  enum class Phase { kHeader, kData, kDescriptor, kCentral, kDone };

  bool Zip64(uint64_t value) const { return value >= zip64_from_; }
  bool EntryZip64(size_t index) const;
  void LocalHeader(std::string& out);
  void Data(std::string& out);
  void Descriptor(std::string& out);
  void CentralDirectory(std::string& out);

  std::vector<ZipEntry> entries_;
  uint64_t zip64_from_;
  std::vector<Written> written_;
  size_t index_ = 0;
  Phase phase_ = Phase::kHeader;
  uint64_t offset_ = 0;
  std::ifstream file_;
  uint64_t file_read_ = 0;
  uint32_t crc_ = 0;
  std::unique_ptr<storage::Sha256> sha256_;
};

}  // namespace omnirig::server
