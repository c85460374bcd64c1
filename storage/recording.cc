// Opening a recording: the container is recognised by its first bytes (or, for a folder, by its
// metadata.yaml), then the reader of its format indexes it. Also what the readers share.

#include "storage/recording.h"

#include <bzlib.h>
#include <fcntl.h>
#include <lz4frame.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zstd.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <cstring>
#include <fstream>

#include "storage/recording_format.h"

namespace omnirig::storage {
namespace recording {

namespace fs = std::filesystem;

MappedFile::MappedFile(const fs::path& path) {
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (fd < 0) {
    throw RecordingError(path.filename().string() + ": cannot open: " + std::strerror(errno));
  }
  struct stat st {};
  if (::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
    ::close(fd);
    throw RecordingError(path.filename().string() + ": not a regular file");
  }
  size_ = static_cast<uint64_t>(st.st_size);
  if (size_ > 0) {
    void* mapped = ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd, 0);
    if (mapped == MAP_FAILED) {
      ::close(fd);
      throw RecordingError(path.filename().string() + ": cannot map: " + std::strerror(errno));
    }
    data_ = static_cast<const uint8_t*>(mapped);
  }
  ::close(fd);  // the mapping holds the file
}

MappedFile::~MappedFile() {
  if (data_) ::munmap(const_cast<uint8_t*>(data_), size_);
}

Bytes MapWhole(const fs::path& path, const std::string& label) {
  auto file = std::make_shared<const MappedFile>(path);
  return Bytes{file, file->data(), file->size(), 0, label, path};
}

void Fail(const Bytes& bytes, uint64_t offset, const std::string& problem) {
  throw RecordingError(bytes.label, bytes.file_offset + offset, problem);
}

namespace {

void DecompressBz2(std::string_view input, std::string& output, const Bytes& bytes,
                   uint64_t offset) {
  unsigned int size = static_cast<unsigned int>(output.size());
  const int status = BZ2_bzBuffToBuffDecompress(output.data(), &size,
                                                const_cast<char*>(input.data()),
                                                static_cast<unsigned int>(input.size()), 0, 0);
  if (status != BZ_OK) {
    Fail(bytes, offset,
         "bz2 chunk does not decompress (" +
             std::string(status == BZ_OUTBUFF_FULL ? "larger than its declared size"
                         : status == BZ_UNEXPECTED_EOF ? "cut short"
                                                       : "damaged data") +
             ")");
  }
  output.resize(size);
}

void DecompressLz4(std::string_view input, std::string& output, const Bytes& bytes,
                   uint64_t offset) {
  LZ4F_dctx* context = nullptr;
  if (LZ4F_isError(LZ4F_createDecompressionContext(&context, LZ4F_VERSION))) {
    throw std::bad_alloc();
  }
  size_t in_pos = 0, out_pos = 0;
  size_t hint = 1;
  while (hint != 0 && in_pos < input.size()) {
    size_t in_size = input.size() - in_pos, out_size = output.size() - out_pos;
    hint = LZ4F_decompress(context, output.data() + out_pos, &out_size, input.data() + in_pos,
                           &in_size, nullptr);
    if (LZ4F_isError(hint)) {
      const std::string name = LZ4F_getErrorName(hint);
      LZ4F_freeDecompressionContext(context);
      Fail(bytes, offset, "lz4 chunk does not decompress (" + name + ")");
    }
    in_pos += in_size;
    out_pos += out_size;
    if (out_size == 0 && in_size == 0) break;
  }
  LZ4F_freeDecompressionContext(context);
  if (hint != 0) Fail(bytes, offset, "lz4 chunk is cut short (its frame does not end)");
  output.resize(out_pos);
}

void DecompressZstd(std::string_view input, std::string& output, const Bytes& bytes,
                    uint64_t offset) {
  const size_t size = ZSTD_decompress(output.data(), output.size(), input.data(), input.size());
  if (ZSTD_isError(size)) {
    Fail(bytes, offset, std::string("zstd chunk does not decompress (") +
                            ZSTD_getErrorName(size) + ")");
  }
  output.resize(size);
}

}  // namespace

void Decompress(const std::string& compression, std::string_view input, uint64_t expected_size,
                std::string& output, const Bytes& bytes, uint64_t offset) {
  // Recorders write chunks of about a megabyte (ROS 1: 768 KiB, MCAP: 4 MiB by default); a
  // header that declares more than this is damaged, and believing it would reserve the memory.
  constexpr uint64_t kMaxChunkBytes = 256ull << 20;
  if (expected_size > kMaxChunkBytes) {
    Fail(bytes, offset,
         "chunk declares " + std::to_string(expected_size) +
             " bytes uncompressed, more than any recorder writes in one chunk (256 MiB)");
  }
  output.resize(expected_size);
  if (compression == "bz2") {
    DecompressBz2(input, output, bytes, offset);
  } else if (compression == "lz4") {
    DecompressLz4(input, output, bytes, offset);
  } else if (compression == "zstd") {
    DecompressZstd(input, output, bytes, offset);
  } else {
    Fail(bytes, offset, "chunk compression '" + compression + "' is not one omnirig reads "
                        "(none, bz2, lz4, zstd)");
  }
  if (output.size() != expected_size) {
    Fail(bytes, offset,
         "chunk decompresses to " + std::to_string(output.size()) + " bytes, not the " +
             std::to_string(expected_size) + " its header declares");
  }
}

void AddTopics(const std::map<int64_t, RecordingTopic>& topics, RecordingIndex& index) {
  for (const auto& entry : topics) {
    const RecordingTopic& topic = entry.second;
    auto same = std::find_if(index.topics.begin(), index.topics.end(),
                             [&](const RecordingTopic& t) { return t.name == topic.name; });
    if (same == index.topics.end()) {
      index.topics.push_back(topic);
    } else if (topic.message_count > 0) {
      if (same->message_count == 0 || topic.first_time_ns < same->first_time_ns)
        same->first_time_ns = topic.first_time_ns;
      if (same->message_count == 0 || topic.last_time_ns > same->last_time_ns)
        same->last_time_ns = topic.last_time_ns;
      same->message_count += topic.message_count;
    }
    index.message_count += topic.message_count;
  }
  std::sort(index.topics.begin(), index.topics.end(),
            [](const RecordingTopic& a, const RecordingTopic& b) { return a.name < b.name; });
}

namespace {

std::string Lower(std::string text) {
  for (char& c : text) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

bool EndsWith(const std::string& text, const std::string& suffix) {
  return text.size() >= suffix.size() &&
         text.compare(text.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// ---- tar (POSIX ustar and GNU): members are contiguous byte ranges of the archive ----------

struct TarMember {
  std::string name;
  uint64_t offset = 0, size = 0;
};

uint64_t TarNumber(const Bytes& bytes, uint64_t at, const uint8_t* field, int width) {
  if (field[0] & 0x80) {  // GNU base-256 for sizes of 8 GiB and more
    uint64_t value = field[0] & 0x7f;
    for (int i = 1; i < width; ++i) value = (value << 8) | field[i];
    return value;
  }
  uint64_t value = 0;
  int i = 0;
  while (i < width && field[i] == ' ') ++i;
  for (; i < width && field[i] >= '0' && field[i] <= '7'; ++i) value = value * 8 + (field[i] - '0');
  if (i < width && field[i] != 0 && field[i] != ' ') Fail(bytes, at, "tar header has a bad number");
  return value;
}

std::vector<TarMember> ListTar(const Bytes& bytes) {
  std::vector<TarMember> members;
  std::string long_name;
  for (uint64_t pos = 0;;) {
    if (bytes.size - pos < 512) Fail(bytes, pos, "tar archive ends inside a member header");
    const uint8_t* header = bytes.data + pos;
    if (std::all_of(header, header + 512, [](uint8_t b) { return b == 0; })) break;  // end
    uint64_t checksum = 0;
    for (int i = 0; i < 512; ++i) checksum += (i >= 148 && i < 156) ? ' ' : header[i];
    if (checksum != TarNumber(bytes, pos, header + 148, 8)) {
      Fail(bytes, pos, "tar member header's checksum does not match (damaged or not a tar)");
    }
    const uint64_t size = TarNumber(bytes, pos, header + 124, 12);
    const uint64_t data = pos + 512;
    if (size > bytes.size - data) {
      Fail(bytes, pos, "tar member declares " + std::to_string(size) + " bytes but the archive "
                       "ends after " + std::to_string(bytes.size - data) + " (cut short)");
    }
    const char type = static_cast<char>(header[156]);
    std::string name(reinterpret_cast<const char*>(header), strnlen(reinterpret_cast<const char*>(header), 100));
    if (std::memcmp(header + 257, "ustar", 5) == 0 && header[345] != 0) {
      name = std::string(reinterpret_cast<const char*>(header + 345),
                         strnlen(reinterpret_cast<const char*>(header + 345), 155)) + "/" + name;
    }
    if (type == 'L') {  // GNU long name: the next member's name
      long_name.assign(reinterpret_cast<const char*>(bytes.data + data), size);
      long_name.resize(strnlen(long_name.c_str(), long_name.size()));
    } else if (type == '0' || type == '\0') {
      if (!long_name.empty()) name = std::move(long_name);
      long_name.clear();
      while (name.rfind("./", 0) == 0) name.erase(0, 2);
      members.push_back({name, data, size});
    } else {
      long_name.clear();  // folders, links, pax headers: not files of a bag
    }
    pos = data + (size + 511) / 512 * 512;
    if (pos >= bytes.size) break;  // some writers omit the two zero blocks
  }
  return members;
}

Bytes Member(const Bytes& archive, const TarMember& member) {
  return Bytes{archive.file, archive.data + member.offset, member.size,
               archive.file_offset + member.offset, archive.label + ":" + member.name, {}};
}

std::unique_ptr<Recording> OpenTar(const Bytes& archive) {
  const std::vector<TarMember> members = ListTar(archive);
  const TarMember* metadata = nullptr;
  for (const auto& member : members) {
    if (fs::path(member.name).filename() == "metadata.yaml" &&
        (!metadata || member.name.size() < metadata->name.size())) {
      metadata = &member;
    }
  }
  if (!metadata) {
    throw RecordingError(archive.label + ": the archive holds no metadata.yaml: a .tar is taken "
                         "as a ROS 2 bag's folder (metadata.yaml with its .db3 or .mcap files)");
  }
  const fs::path folder = fs::path(metadata->name).parent_path();
  return OpenRos2Bag(Member(archive, *metadata), [&](const std::string& relative) {
    const std::string wanted = (folder / relative).lexically_normal().string();
    for (const auto& member : members) {
      if (fs::path(member.name).lexically_normal().string() == wanted) {
        return Member(archive, member);
      }
    }
    throw RecordingError(archive.label + ": metadata.yaml lists " + relative +
                         ", which the archive does not hold");
  });
}

std::unique_ptr<Recording> OpenFolder(const fs::path& folder) {
  const fs::path metadata = folder / "metadata.yaml";
  if (!fs::exists(metadata)) {
    throw RecordingError(folder.filename().string() + ": the folder holds no metadata.yaml");
  }
  const std::string name = folder.filename().string();
  return OpenRos2Bag(MapWhole(metadata, name + "/metadata.yaml"),
                     [&](const std::string& relative) {
                       const fs::path path = folder / relative;
                       if (!fs::exists(path)) {
                         throw RecordingError(name + ": metadata.yaml lists " + relative +
                                              ", which the folder does not hold");
                       }
                       return MapWhole(path, name + "/" + relative);
                     });
}

}  // namespace
}  // namespace recording

bool IsRecordingName(const std::string& name) {
  const std::string lower = recording::Lower(name);
  for (const char* suffix : {".bag", ".mcap", ".db3", ".tar"}) {
    if (recording::EndsWith(lower, suffix)) return true;
  }
  return std::filesystem::path(lower).filename() == "metadata.yaml";
}

double RecordingTopic::rate_hz() const {
  if (message_count < 2 || last_time_ns <= first_time_ns) return 0;
  return static_cast<double>(message_count - 1) * 1e9 /
         static_cast<double>(last_time_ns - first_time_ns);
}

const RecordingTopic* Recording::FindTopic(const std::string& name) const {
  for (const auto& topic : index_.topics) {
    if (topic.name == name) return &topic;
  }
  return nullptr;
}

void Recording::ReadMessages(const std::set<std::string>& topics,
                             const std::function<bool(const RecordingMessage&)>& on_message) const {
  std::vector<bool> wanted(index_.topics.size(), topics.empty());
  for (const auto& name : topics) {
    const RecordingTopic* topic = FindTopic(name);
    if (!topic) throw std::invalid_argument("the recording holds no topic " + name);
    wanted[static_cast<size_t>(topic - index_.topics.data())] = true;
  }
  Read(wanted, on_message);
}

std::unique_ptr<Recording> Recording::Open(const std::filesystem::path& path,
                                           const std::string& label_or_empty) {
  using namespace recording;
  if (std::filesystem::is_directory(path)) return OpenFolder(path);
  const std::string label = label_or_empty.empty() ? path.filename().string() : label_or_empty;
  if (path.filename() == "metadata.yaml") return OpenFolder(path.parent_path());
  Bytes bytes = MapWhole(path, label);
  const auto starts = [&](std::string_view magic) {
    return bytes.size >= magic.size() && std::memcmp(bytes.data, magic.data(), magic.size()) == 0;
  };
  if (starts("#ROSBAG V2.0\n")) return OpenRos1Bag(std::move(bytes));
  if (starts("#ROSBAG V")) {
    Fail(bytes, 0, "ROS 1 bag format " +
                       std::string(reinterpret_cast<const char*>(bytes.data) + 9,
                                   std::min<uint64_t>(3, bytes.size - 9)) +
                       " is not read: omnirig reads format 2.0 (rosbag since ROS C Turtle)");
  }
  if (starts("\x89MCAP0\r\n")) return OpenMcap(std::move(bytes));
  if (starts("SQLite format 3")) {
    Fail(bytes, 0, "a .db3 alone is no recording: upload its ROS 2 bag's folder (metadata.yaml "
                   "with its .db3 files) or a .tar of it");
  }
  if (bytes.size >= 512 && std::memcmp(bytes.data + 257, "ustar", 5) == 0) return OpenTar(bytes);
  Fail(bytes, 0, "not a recording omnirig reads: a ROS 1 bag begins with '#ROSBAG V2.0', an MCAP "
                 "file with its magic \\x89MCAP0, a ROS 2 bag is a folder (or .tar) with "
                 "metadata.yaml");
}

std::optional<RecordingIndex> CheckRecordingFile(const std::string& name,
                                                 const std::filesystem::path& path) {
  using namespace recording;
  const std::string lower = Lower(name);
  if (EndsWith(lower, ".db3")) {
    Bytes bytes = MapWhole(path, name);
    if (bytes.size < 16 || std::memcmp(bytes.data, "SQLite format 3", 16) != 0) {
      Fail(bytes, 0, "not an SQLite file (a ROS 2 bag's .db3 begins with 'SQLite format 3')");
    }
    OpenDb3(std::move(bytes));
    return std::nullopt;
  }
  if (std::filesystem::path(lower).filename() == "metadata.yaml") {
    CheckRos2Metadata(MapWhole(path, name));
    return std::nullopt;
  }
  return Recording::Open(path, name)->index();
}

}  // namespace omnirig::storage
