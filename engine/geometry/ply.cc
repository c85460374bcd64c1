#include "engine/geometry/ply.h"

#include <cstring>
#include <fstream>
#include <stdexcept>
#include <type_traits>
#include <utility>

#include "engine/util/check.h"

namespace omnirig {
namespace {

template <typename T>
void AppendLittleEndian(const T& value, std::string* out) {
  static_assert(std::is_trivially_copyable<T>::value, "plain values only");
  char bytes[sizeof(T)];
  std::memcpy(bytes, &value, sizeof(T));
  // PLY says little-endian explicitly; swap on the (rare) big-endian host.
  const std::uint16_t probe = 1;
  if (*reinterpret_cast<const std::uint8_t*>(&probe) == 0) {
    for (size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(bytes[i], bytes[sizeof(T) - 1 - i]);
  }
  out->append(bytes, sizeof(T));
}

}  // namespace

void PlyCloud::Check() const {
  OMNIRIG_CHECK(colours.size() == positions.size(),
                "PLY cloud: " << colours.size() << " colours for " << positions.size()
                              << " positions");
  OMNIRIG_CHECK(confidence.size() == (has_confidence ? positions.size() : 0),
                "PLY cloud: " << confidence.size() << " confidences for " << positions.size()
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
  if (cloud.has_num_observations) data += "property int num_observations\n";
  data += "end_header\n";
  return data;
}

void AppendVertices(const PlyCloud& cloud, std::string* data) {
  const size_t vertex_bytes = 15 + 4 * cloud.has_confidence + 4 * cloud.has_num_observations;
  data->reserve(data->size() + vertex_bytes * cloud.size());
  for (size_t i = 0; i < cloud.size(); ++i) {
    for (int k = 0; k < 3; ++k) AppendLittleEndian(cloud.positions[i][k], data);
    for (int k = 0; k < 3; ++k) AppendLittleEndian(cloud.colours[i][k], data);
    if (cloud.has_confidence) AppendLittleEndian(cloud.confidence[i], data);
    if (cloud.has_num_observations) AppendLittleEndian(cloud.num_observations[i], data);
  }
}

void WriteBytes(const std::filesystem::path& path, const std::string& data,
                std::ios::openmode mode) {
  std::ofstream out(path, std::ios::out | std::ios::binary | mode);
  if (!out) throw std::runtime_error("cannot write " + path.string());
  out.write(data.data(), static_cast<std::streamsize>(data.size()));
  if (!out) throw std::runtime_error("failed writing " + path.string());
}

std::filesystem::path PartPath(const std::filesystem::path& path) {
  return std::filesystem::path(path.string() + ".part");
}

}  // namespace

void WritePly(const std::filesystem::path& path, const PlyCloud& cloud) {
  cloud.Check();
  std::string data = Header(cloud, cloud.size());
  AppendVertices(cloud, &data);
  WriteBytes(path, data, std::ios::trunc);
}

PlyAppender::PlyAppender(std::filesystem::path path) : path_(std::move(path)) {}

void PlyAppender::Append(const PlyCloud& part) {
  part.Check();
  if (!started_) {
    header_.comment = part.comment;
    header_.has_confidence = part.has_confidence;
    header_.has_num_observations = part.has_num_observations;
  }
  OMNIRIG_CHECK(part.has_confidence == header_.has_confidence &&
                    part.has_num_observations == header_.has_num_observations,
                "PLY parts must have the same properties");
  std::string data;
  AppendVertices(part, &data);
  WriteBytes(PartPath(path_), data, started_ ? std::ios::app : std::ios::trunc);
  started_ = true;
  count_ += part.size();
}

void PlyAppender::Finish() {
  WriteBytes(path_, Header(header_, count_), std::ios::trunc);
  if (count_ > 0) {
    std::ifstream in(PartPath(path_), std::ios::binary);
    std::ofstream out(path_, std::ios::out | std::ios::binary | std::ios::app);
    if (!in || !out) throw std::runtime_error("cannot write " + path_.string());
    out << in.rdbuf();
    if (!out) throw std::runtime_error("failed writing " + path_.string());
  }
  std::filesystem::remove(PartPath(path_));
}

}  // namespace omnirig
