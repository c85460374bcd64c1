#include "engine/geometry/ply.h"

#include <algorithm>
#include <cstring>
#include <fstream>
#include <stdexcept>
#include <utility>
#include <vector>

#include "engine/util/check.h"

namespace omnirig {
namespace {

// PLY says little-endian explicitly; the body is packed with memcpy in the host's order and
// swapped afterwards on the (rare) big-endian host.
bool HostIsBigEndian() {
  const std::uint16_t probe = 1;
  std::uint8_t first;
  std::memcpy(&first, &probe, 1);
  return first == 0;
}

}  // namespace

void PlyCloud::Check() const {
  OMNIRIG_CHECK(colours.size() == positions.size(),
                "PLY cloud: " << colours.size() << " colours for " << positions.size()
                              << " positions");
  OMNIRIG_CHECK(confidence.size() == (has_confidence ? positions.size() : 0),
                "PLY cloud: " << confidence.size() << " confidences for " << positions.size()
                              << " positions");
  OMNIRIG_CHECK(range_std_m.size() == (has_range_std ? positions.size() : 0),
                "PLY cloud: " << range_std_m.size() << " range stds for " << positions.size()
                              << " positions");
  OMNIRIG_CHECK(num_observations.size() == (has_num_observations ? positions.size() : 0),
                "PLY cloud: " << num_observations.size() << " observation counts for "
                              << positions.size() << " positions");
  OMNIRIG_CHECK(comment.find('\n') == std::string::npos, "PLY comment holds a newline");
}

namespace {

std::string Header(const PlyCloud& cloud, size_t count) {
  std::string data = "ply\nformat binary_little_endian 1.0\n";
  if (!cloud.comment.empty()) data += "comment " + cloud.comment + "\n";
  data += "element vertex " + std::to_string(count) + "\n";
  data += "property float x\nproperty float y\nproperty float z\n";
  data += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  if (cloud.has_confidence) data += "property float confidence\n";
  if (cloud.has_range_std) data += "property float range_std_m\n";
  if (cloud.has_num_observations) data += "property int num_observations\n";
  data += "end_header\n";
  return data;
}

size_t VertexBytes(const PlyCloud& cloud) {
  return 15 + 4 * cloud.has_confidence + 4 * cloud.has_range_std + 4 * cloud.has_num_observations;
}

// Packs vertices [begin, end) into `out` (VertexBytes each), one memcpy of a fixed size per
// value: appending value by value to a string made a dense pair's 940,000 vertices cost 0.083
// CPU s to write; packed, the whole write costs 0.013 (bench_dense).
void PackVertices(const PlyCloud& cloud, size_t begin, size_t end, char* out) {
  const size_t stride = VertexBytes(cloud);
  for (size_t i = begin; i < end; ++i, out += stride) {
    std::memcpy(out, cloud.positions[i].data(), 12);
    std::memcpy(out + 12, cloud.colours[i].data(), 3);
    char* next = out + 15;
    if (cloud.has_confidence) {
      std::memcpy(next, &cloud.confidence[i], 4);
      next += 4;
    }
    if (cloud.has_range_std) {
      std::memcpy(next, &cloud.range_std_m[i], 4);
      next += 4;
    }
    if (cloud.has_num_observations) std::memcpy(next, &cloud.num_observations[i], 4);
  }
  if (!HostIsBigEndian()) return;
  out -= stride * (end - begin);
  const int num_words =  // 4-byte values
      4 + cloud.has_confidence + cloud.has_range_std + cloud.has_num_observations;
  for (size_t i = begin; i < end; ++i, out += stride) {
    for (int w = 0; w < num_words; ++w) {
      char* value = out + 4 * w + (w >= 3 ? 3 : 0);  // the 3 colour bytes sit before word 3
      std::swap(value[0], value[3]);
      std::swap(value[1], value[2]);
    }
  }
}

std::ofstream OpenForWriting(const std::filesystem::path& path, std::ios::openmode mode) {
  std::ofstream out(path, std::ios::out | std::ios::binary | mode);
  if (!out) throw std::runtime_error("cannot write " + path.string());
  return out;
}

// Writes the cloud's vertices in chunks of about 1 MB (a dense pair's body is 18 MB: one
// chunk stays in the cache between packing and writing, and the whole body is never copied).
void WriteVertices(const PlyCloud& cloud, const std::filesystem::path& path, std::ofstream* out) {
  const size_t stride = VertexBytes(cloud), chunk = 1 << 16;
  std::vector<char> buffer(stride * std::min(chunk, cloud.size()));
  for (size_t begin = 0; begin < cloud.size(); begin += chunk) {
    const size_t end = std::min(cloud.size(), begin + chunk);
    PackVertices(cloud, begin, end, buffer.data());
    out->write(buffer.data(), static_cast<std::streamsize>(stride * (end - begin)));
  }
  out->flush();
  if (!*out) throw std::runtime_error("failed writing " + path.string());
}

std::filesystem::path PartPath(const std::filesystem::path& path) {
  return std::filesystem::path(path.string() + ".part");
}

}  // namespace

void WritePly(const std::filesystem::path& path, const PlyCloud& cloud) {
  cloud.Check();
  std::ofstream out = OpenForWriting(path, std::ios::trunc);
  out << Header(cloud, cloud.size());
  WriteVertices(cloud, path, &out);
}

PlyAppender::PlyAppender(std::filesystem::path path) : path_(std::move(path)) {}

void PlyAppender::Append(const PlyCloud& part) {
  part.Check();
  if (!started_) {
    header_.comment = part.comment;
    header_.has_confidence = part.has_confidence;
    header_.has_range_std = part.has_range_std;
    header_.has_num_observations = part.has_num_observations;
  }
  OMNIRIG_CHECK(part.has_confidence == header_.has_confidence &&
                    part.has_range_std == header_.has_range_std &&
                    part.has_num_observations == header_.has_num_observations,
                "PLY parts must have the same properties");
  std::ofstream out = OpenForWriting(PartPath(path_), started_ ? std::ios::app : std::ios::trunc);
  WriteVertices(part, PartPath(path_), &out);
  started_ = true;
  count_ += part.size();
}

void PlyAppender::Finish() {
  std::ofstream out = OpenForWriting(path_, std::ios::trunc);
  out << Header(header_, count_);
  if (count_ > 0) {
    std::ifstream in(PartPath(path_), std::ios::binary);
    if (!in) throw std::runtime_error("cannot read " + PartPath(path_).string());
    out << in.rdbuf();
  }
  out.flush();
  if (!out) throw std::runtime_error("failed writing " + path_.string());
  std::filesystem::remove(PartPath(path_));
}

}  // namespace omnirig
