#include "engine/slam/map_io.h"

#include <cstring>
#include <fstream>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include "engine/util/check.h"

namespace omnirig::slam {
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

std::ofstream OpenForWriting(const std::filesystem::path& path, std::ios::openmode mode) {
  std::ofstream out(path, mode);
  if (!out) throw std::runtime_error("cannot write " + path.string());
  return out;
}

}  // namespace

void WriteTum(const std::filesystem::path& path, const std::vector<StampedPose>& poses) {
  std::ofstream out = OpenForWriting(path, std::ios::out | std::ios::trunc);
  out << "# timestamp tx ty tz qx qy qz qw (world_from_rig)\n" << std::setprecision(17);
  for (const StampedPose& pose : poses) {
    // Adding +0.0 turns negative zeros (from inverting the identity) into plain zeros.
    const Eigen::Vector3d t = pose.world_from_rig.translation + Eigen::Vector3d::Zero();
    Eigen::Quaterniond q = pose.world_from_rig.rotation.normalized();
    q.coeffs() += Eigen::Vector4d::Zero();
    out << pose.timestamp_s << ' ' << t.x() << ' ' << t.y() << ' ' << t.z() << ' ' << q.x()
        << ' ' << q.y() << ' ' << q.z() << ' ' << q.w() << '\n';
  }
  if (!out) throw std::runtime_error("failed writing " + path.string());
}

std::vector<StampedPose> ReadTum(const std::filesystem::path& path) {
  std::ifstream in(path);
  OMNIRIG_CHECK(in, "cannot open the TUM trajectory " << path.filename().string());
  std::vector<StampedPose> poses;
  std::string line;
  int line_number = 0;
  while (std::getline(in, line)) {
    ++line_number;
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    std::istringstream fields(line);
    double v[8];
    for (double& value : v) {
      OMNIRIG_CHECK(static_cast<bool>(fields >> value),
                    path.filename().string() << " line " << line_number
                                             << ": expected 'timestamp tx ty tz qx qy qz qw'");
    }
    const Eigen::Quaterniond q(v[7], v[4], v[5], v[6]);
    OMNIRIG_CHECK(q.norm() > 0.5 && q.norm() < 2.0,
                  path.filename().string() << " line " << line_number
                                           << ": quaternion is not close to unit length");
    poses.push_back({v[0], Rigid3d(q, Eigen::Vector3d(v[1], v[2], v[3]))});
  }
  return poses;
}

void WritePly(const std::filesystem::path& path, const std::vector<MapPoint>& points) {
  std::ostringstream header;
  header << "ply\nformat binary_little_endian 1.0\ncomment omnirig SLAM map, metres\n"
         << "element vertex " << points.size() << "\n"
         << "property float x\nproperty float y\nproperty float z\n"
         << "property uchar red\nproperty uchar green\nproperty uchar blue\n"
         << "property int num_observations\nend_header\n";
  std::string body;
  body.reserve(points.size() * 19);
  for (const MapPoint& point : points) {
    for (int i = 0; i < 3; ++i) AppendLittleEndian(static_cast<float>(point.point_in_world[i]), &body);
    for (int i = 0; i < 3; ++i) AppendLittleEndian(point.rgb[i], &body);
    AppendLittleEndian(static_cast<std::int32_t>(point.num_observations), &body);
  }
  std::ofstream out = OpenForWriting(path, std::ios::out | std::ios::binary | std::ios::trunc);
  out << header.str();
  out.write(body.data(), static_cast<std::streamsize>(body.size()));
  if (!out) throw std::runtime_error("failed writing " + path.string());
}

}  // namespace omnirig::slam
