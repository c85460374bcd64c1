#include "engine/geometry/ply.h"

#include <cstring>
#include <fstream>
#include <stdexcept>
#include <type_traits>

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

void WritePly(const std::filesystem::path& path, const PlyCloud& cloud) {
  cloud.Check();
  std::string data = "ply\nformat binary_little_endian 1.0\n";
  if (!cloud.comment.empty()) data += "comment " + cloud.comment + "\n";
  data += "element vertex " + std::to_string(cloud.size()) + "\n";
  data += "property float x\nproperty float y\nproperty float z\n";
  data += "property uchar red\nproperty uchar green\nproperty uchar blue\n";
  if (cloud.has_confidence) data += "property float confidence\n";
  if (cloud.has_num_observations) data += "property int num_observations\n";
  data += "end_header\n";
  const size_t vertex_bytes = 15 + 4 * cloud.has_confidence +
                              4 * cloud.has_num_observations;
  data.reserve(data.size() + vertex_bytes * cloud.size());
  for (size_t i = 0; i < cloud.size(); ++i) {
    for (int k = 0; k < 3; ++k) AppendLittleEndian(cloud.positions[i][k], &data);
    for (int k = 0; k < 3; ++k) AppendLittleEndian(cloud.colours[i][k], &data);
    if (cloud.has_confidence) AppendLittleEndian(cloud.confidence[i], &data);
    if (cloud.has_num_observations) AppendLittleEndian(cloud.num_observations[i], &data);
  }
  std::ofstream out(path, std::ios::out | std::ios::binary | std::ios::trunc);
  if (!out) throw std::runtime_error("cannot write " + path.string());
  out.write(data.data(), static_cast<std::streamsize>(data.size()));
  if (!out) throw std::runtime_error("failed writing " + path.string());
}

}  // namespace omnirig
