#pragma once
// Files a SLAM run writes and reads: TUM trajectories (the format of the TUM RGB-D benchmark,
// read by evo and similar tools) and binary PLY point clouds (read by Open3D, PCL, MeshLab,
// CloudCompare).

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "engine/geometry/rigid3.h"

namespace omnirig::slam {

// One line of a TUM file: "timestamp tx ty tz qx qy qz qw", the pose being world_from_rig.
struct StampedPose {
  double timestamp_s = 0.0;
  Rigid3d world_from_rig;
};

// Writes one pose per line with full double precision. Throws std::runtime_error when the file
// cannot be written.
void WriteTum(const std::filesystem::path& path, const std::vector<StampedPose>& poses);

// Writes the poses in the KITTI odometry format the evaluation tools read (evo_traj kitti): per
// line the first three rows of world_from_rig's 4x4 matrix, row-major, no timestamps (the
// TUM file carries them). Throws std::runtime_error when the file cannot be written.
void WriteKitti(const std::filesystem::path& path, const std::vector<StampedPose>& poses);

// Reads a TUM file; '#' lines and blank lines are skipped. Throws InvalidArgument naming the
// line when one does not hold eight numbers, or when the file cannot be opened.
std::vector<StampedPose> ReadTum(const std::filesystem::path& path);

// A coloured map point with the number of image observations that support it.
struct MapPoint {
  Eigen::Vector3d point_in_world;
  std::array<std::uint8_t, 3> rgb{0, 0, 0};
  int num_observations = 0;
};

// Binary little-endian PLY (engine/geometry/ply.h): "vertex" with float x y z (metres), uchar
// red green blue, and int num_observations (19 bytes per vertex).
void WritePly(const std::filesystem::path& path, const std::vector<MapPoint>& points);

}  // namespace omnirig::slam
