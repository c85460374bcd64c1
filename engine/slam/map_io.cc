#include "engine/slam/map_io.h"

#include <fstream>
#include <iomanip>
#include <sstream>
#include <stdexcept>

#include "engine/geometry/ply.h"
#include "engine/util/check.h"

namespace omnirig::slam {
namespace {

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

void WriteKitti(const std::filesystem::path& path, const std::vector<StampedPose>& poses) {
  std::ofstream out = OpenForWriting(path, std::ios::out | std::ios::trunc);
  out << std::setprecision(17);
  for (const StampedPose& pose : poses) {
    const Eigen::Matrix3d r = pose.world_from_rig.rotation.normalized().toRotationMatrix();
    const Eigen::Vector3d& t = pose.world_from_rig.translation;
    for (int row = 0; row < 3; ++row) {
      // Adding +0.0 turns negative zeros into plain zeros, as in the TUM file.
      out << r(row, 0) + 0.0 << ' ' << r(row, 1) + 0.0 << ' ' << r(row, 2) + 0.0 << ' '
          << t(row) + 0.0 << (row == 2 ? '\n' : ' ');
    }
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
  PlyCloud cloud;
  cloud.comment = "omnirig SLAM map, metres";
  cloud.has_num_observations = true;
  for (const MapPoint& point : points) {
    cloud.positions.push_back(point.point_in_world.cast<float>());
    cloud.colours.push_back(point.rgb);
    cloud.num_observations.push_back(static_cast<std::int32_t>(point.num_observations));
  }
  omnirig::WritePly(path, cloud);
}

}  // namespace omnirig::slam
