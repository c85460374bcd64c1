#include "server/zip_stream.h"

#include <sys/stat.h>
#include <zlib.h>

#include <algorithm>
#include <ctime>
#include <stdexcept>

namespace omnirig::server {
namespace {

constexpr uint32_t kLocalHeaderSignature = 0x04034b50;
constexpr uint32_t kDescriptorSignature = 0x08074b50;
constexpr uint32_t kCentralSignature = 0x02014b50;
constexpr uint32_t kZip64EndSignature = 0x06064b50;
constexpr uint32_t kZip64LocatorSignature = 0x07064b50;
constexpr uint32_t kEndSignature = 0x06054b50;
constexpr uint16_t kFlags = 0x0008 | 0x0800;  // sizes in the data descriptor; UTF-8 names
constexpr uint16_t kVersionClassic = 20, kVersionZip64 = 45;
constexpr uint16_t kMadeByUnix = 3 << 8;
constexpr uint16_t kZip64ExtraId = 0x0001;
constexpr size_t kBlockBytes = 256 * 1024;

void Put16(std::string& out, uint16_t value) {
  out += static_cast<char>(value & 0xFF);
  out += static_cast<char>(value >> 8);
}
void Put32(std::string& out, uint32_t value) {
  Put16(out, static_cast<uint16_t>(value & 0xFFFF));
  Put16(out, static_cast<uint16_t>(value >> 16));
}
void Put64(std::string& out, uint64_t value) {
  Put32(out, static_cast<uint32_t>(value & 0xFFFFFFFFu));
  Put32(out, static_cast<uint32_t>(value >> 32));
}

// MS-DOS time and date (local fields of the format; written in UTC) of the file's mtime.
void DosTime(const std::filesystem::path& path, uint16_t& dos_time, uint16_t& dos_date) {
  struct stat info {};
  std::time_t seconds = ::stat(path.c_str(), &info) == 0 ? info.st_mtime : std::time(nullptr);
  std::tm utc{};
  gmtime_r(&seconds, &utc);
  if (utc.tm_year < 80) {  // the format starts in 1980
    utc = std::tm{};
    utc.tm_year = 80;
    utc.tm_mday = 1;
  }
  dos_time = static_cast<uint16_t>((utc.tm_hour << 11) | (utc.tm_min << 5) | (utc.tm_sec / 2));
  dos_date = static_cast<uint16_t>(((utc.tm_year - 80) << 9) | ((utc.tm_mon + 1) << 5) |
                                   utc.tm_mday);
}

}  // namespace

ZipStream::ZipStream(std::vector<ZipEntry> entries, uint64_t zip64_from)
    : entries_(std::move(entries)), zip64_from_(zip64_from) {
  written_.resize(entries_.size());
  if (entries_.empty()) phase_ = Phase::kCentral;
}

bool ZipStream::EntryZip64(size_t index) const {
  return Zip64(static_cast<uint64_t>(entries_[index].size)) ||
         Zip64(written_[index].header_offset);
}

bool ZipStream::Next(std::string& out) {
  const size_t before = out.size();
  switch (phase_) {
    case Phase::kHeader:
      LocalHeader(out);
      break;
    case Phase::kData:
      Data(out);
      break;
    case Phase::kDescriptor:
      Descriptor(out);
      break;
    case Phase::kCentral:
      CentralDirectory(out);
      break;
    case Phase::kDone:
      return false;
  }
  offset_ += out.size() - before;
  return true;
}

void ZipStream::LocalHeader(std::string& out) {
  const ZipEntry& entry = entries_[index_];
  Written& written = written_[index_];
  written.header_offset = offset_;
  DosTime(entry.path, written.dos_time, written.dos_date);
  file_ = std::ifstream(entry.path, std::ios::binary);
  if (!file_) throw std::runtime_error("cannot open " + entry.name);
  file_read_ = 0;
  crc_ = static_cast<uint32_t>(crc32(0L, Z_NULL, 0));
  sha256_ = std::make_unique<storage::Sha256>();
  const bool zip64 = EntryZip64(index_);
  Put32(out, kLocalHeaderSignature);
  Put16(out, zip64 ? kVersionZip64 : kVersionClassic);
  Put16(out, kFlags);
  Put16(out, 0);  // stored
  Put16(out, written.dos_time);
  Put16(out, written.dos_date);
  Put32(out, 0);  // CRC-32: in the descriptor
  Put32(out, zip64 ? 0xFFFFFFFFu : 0);
  Put32(out, zip64 ? 0xFFFFFFFFu : 0);
  Put16(out, static_cast<uint16_t>(entry.name.size()));
  Put16(out, zip64 ? 20 : 0);
  out += entry.name;
  if (zip64) {  // sizes 0 here too: the descriptor holds them, 8 bytes each
    Put16(out, kZip64ExtraId);
    Put16(out, 16);
    Put64(out, 0);
    Put64(out, 0);
  }
  phase_ = Phase::kData;
}

void ZipStream::Data(std::string& out) {
  const ZipEntry& entry = entries_[index_];
  const uint64_t size = static_cast<uint64_t>(entry.size);
  const size_t want = static_cast<size_t>(std::min<uint64_t>(kBlockBytes, size - file_read_));
  if (want > 0) {
    const size_t at = out.size();
    out.resize(at + want);
    file_.read(out.data() + at, static_cast<std::streamsize>(want));
    if (file_.gcount() != static_cast<std::streamsize>(want)) {
      throw std::runtime_error(entry.name + " is shorter on disk than its recorded " +
                               std::to_string(size) + " bytes");
    }
    crc_ = static_cast<uint32_t>(
        crc32(crc_, reinterpret_cast<const Bytef*>(out.data() + at), static_cast<uInt>(want)));
    sha256_->Update(out.data() + at, want);
    file_read_ += want;
  }
  if (file_read_ < size) return;
  if (file_.peek() != std::ifstream::traits_type::eof()) {
    throw std::runtime_error(entry.name + " is longer on disk than its recorded " +
                             std::to_string(size) + " bytes");
  }
  if (sha256_->HexDigest() != entry.sha256) {
    throw std::runtime_error(entry.name + " differs on disk from its recorded SHA-256");
  }
  file_.close();
  phase_ = Phase::kDescriptor;
}

void ZipStream::Descriptor(std::string& out) {
  Written& written = written_[index_];
  written.crc32 = crc_;
  written.size = file_read_;
  Put32(out, kDescriptorSignature);
  Put32(out, written.crc32);
  if (EntryZip64(index_)) {
    Put64(out, written.size);
    Put64(out, written.size);
  } else {
    Put32(out, static_cast<uint32_t>(written.size));
    Put32(out, static_cast<uint32_t>(written.size));
  }
  ++index_;
  phase_ = index_ < entries_.size() ? Phase::kHeader : Phase::kCentral;
}

void ZipStream::CentralDirectory(std::string& out) {
  const uint64_t directory_offset = offset_;
  for (size_t i = 0; i < entries_.size(); ++i) {
    const Written& written = written_[i];
    const bool big_size = Zip64(written.size), big_offset = Zip64(written.header_offset);
    std::string extra;
    if (big_size || big_offset) {
      const uint16_t length = static_cast<uint16_t>((big_size ? 16 : 0) + (big_offset ? 8 : 0));
      Put16(extra, kZip64ExtraId);
      Put16(extra, length);
      if (big_size) {
        Put64(extra, written.size);  // uncompressed, then compressed
        Put64(extra, written.size);
      }
      if (big_offset) Put64(extra, written.header_offset);
    }
    const uint16_t version = EntryZip64(i) ? kVersionZip64 : kVersionClassic;
    Put32(out, kCentralSignature);
    Put16(out, kMadeByUnix | version);
    Put16(out, version);
    Put16(out, kFlags);
    Put16(out, 0);
    Put16(out, written.dos_time);
    Put16(out, written.dos_date);
    Put32(out, written.crc32);
    Put32(out, big_size ? 0xFFFFFFFFu : static_cast<uint32_t>(written.size));
    Put32(out, big_size ? 0xFFFFFFFFu : static_cast<uint32_t>(written.size));
    Put16(out, static_cast<uint16_t>(entries_[i].name.size()));
    Put16(out, static_cast<uint16_t>(extra.size()));
    Put16(out, 0);                      // comment
    Put16(out, 0);                      // disk
    Put16(out, 0);                      // internal attributes
    Put32(out, 0100644u << 16);         // a regular file, rw-r--r--
    Put32(out, big_offset ? 0xFFFFFFFFu : static_cast<uint32_t>(written.header_offset));
    out += entries_[i].name;
    out += extra;
  }
  const uint64_t directory_size = offset_ + out.size() - directory_offset;
  const uint64_t count = entries_.size();
  const bool zip64_end =
      count >= 0xFFFF || Zip64(directory_offset) || Zip64(directory_size);
  if (zip64_end) {
    const uint64_t end_offset = directory_offset + directory_size;
    Put32(out, kZip64EndSignature);
    Put64(out, 44);  // the record's size after this field
    Put16(out, kMadeByUnix | kVersionZip64);
    Put16(out, kVersionZip64);
    Put32(out, 0);
    Put32(out, 0);
    Put64(out, count);
    Put64(out, count);
    Put64(out, directory_size);
    Put64(out, directory_offset);
    Put32(out, kZip64LocatorSignature);
    Put32(out, 0);
    Put64(out, end_offset);
    Put32(out, 1);
  }
  Put32(out, kEndSignature);
  Put16(out, 0);
  Put16(out, 0);
  Put16(out, zip64_end ? 0xFFFF : static_cast<uint16_t>(count));
  Put16(out, zip64_end ? 0xFFFF : static_cast<uint16_t>(count));
  Put32(out, zip64_end ? 0xFFFFFFFFu : static_cast<uint32_t>(directory_size));
  Put32(out, zip64_end ? 0xFFFFFFFFu : static_cast<uint32_t>(directory_offset));
  Put16(out, 0);  // comment
  phase_ = Phase::kDone;
}

}  // namespace omnirig::server
