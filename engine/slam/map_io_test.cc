#include "engine/slam/map_io.h"

#include <cstring>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>

#include "engine/util/check.h"

namespace omnirig::slam {
namespace {

std::filesystem::path TempPath(const std::string& name) {
  return std::filesystem::temp_directory_path() /
         ("omnirig_map_io_" + std::to_string(::getpid()) + "_" + name);
}

TEST(Tum, WriteThenReadRoundTrips) {
  std::vector<StampedPose> poses;
  for (int i = 0; i < 5; ++i) {
    poses.push_back({0.1 * i + 1e9, Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.3 * i, Eigen::Vector3d(1, 2, 3).normalized())),
                                      Eigen::Vector3d(i, -0.5 * i, 1e-3 * i))});
  }
  const auto path = TempPath("traj.tum");
  WriteTum(path, poses);
  const std::vector<StampedPose> read = ReadTum(path);
  ASSERT_EQ(read.size(), poses.size());
  for (size_t i = 0; i < poses.size(); ++i) {
    EXPECT_DOUBLE_EQ(read[i].timestamp_s, poses[i].timestamp_s);
    EXPECT_LT((read[i].world_from_rig.translation - poses[i].world_from_rig.translation).norm(), 1e-12);
    EXPECT_LT(RotationDistanceRad(read[i].world_from_rig.rotation, poses[i].world_from_rig.rotation), 1e-9);
  }
  // Field order is "timestamp tx ty tz qx qy qz qw".
  std::ifstream in(path);
  std::string comment, line;
  std::getline(in, comment);
  std::getline(in, line);
  std::istringstream fields(line);
  double v[8];
  for (double& x : v) fields >> x;
  EXPECT_DOUBLE_EQ(v[7], 1.0);  // identity rotation of pose 0: qw last
  std::filesystem::remove(path);
}

TEST(Kitti, ThreeRowsOfTheMatrixPerPose) {
  const Rigid3d pose(Eigen::Quaterniond(Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized())),
                     Eigen::Vector3d(1.5, -2, 0.25));
  const auto path = TempPath("traj.kitti.txt");
  WriteKitti(path, {{0.0, Rigid3d()}, {0.1, pose}});
  std::ifstream in(path);
  std::string line;
  std::vector<std::vector<double>> rows;
  while (std::getline(in, line)) {
    std::istringstream fields(line);
    rows.emplace_back();
    for (double x; fields >> x;) rows.back().push_back(x);
  }
  ASSERT_EQ(rows.size(), 2u);
  const Eigen::Matrix3d r = pose.rotation.toRotationMatrix();
  for (int row = 0; row < 3; ++row) {
    ASSERT_EQ(rows[1].size(), 12u);
    for (int col = 0; col < 3; ++col) EXPECT_NEAR(rows[1][4 * row + col], r(row, col), 1e-15);
    EXPECT_DOUBLE_EQ(rows[1][4 * row + 3], pose.translation(row));
    EXPECT_DOUBLE_EQ(rows[0][4 * row + row], 1.0);
  }
  std::filesystem::remove(path);
}

TEST(Tum, RejectsMalformedLinesNamingTheLine) {
  const auto path = TempPath("bad.tum");
  std::ofstream(path) << "# header\n1 2 3 4 0 0 0 1\n2 2 3 oops\n";
  try {
    ReadTum(path);
    FAIL() << "expected InvalidArgument";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("line 3"), std::string::npos) << e.what();
  }
  std::filesystem::remove(path);
}

TEST(Ply, HeaderAndBinaryBodyParseBack) {
  std::vector<MapPoint> points = {{Eigen::Vector3d(1.5, -2.25, 3.0), {255, 128, 0}, 4},
                                  {Eigen::Vector3d(-0.125, 0.5, 10.0), {1, 2, 3}, 2}};
  const auto path = TempPath("map.ply");
  WritePly(path, points);
  std::ifstream in(path, std::ios::binary);
  std::string line;
  std::vector<std::string> header;
  while (std::getline(in, line) && line != "end_header") header.push_back(line);
  ASSERT_EQ(line, "end_header");
  const std::vector<std::string> expected = {
      "ply", "format binary_little_endian 1.0", "comment omnirig SLAM map, metres",
      "element vertex 2", "property float x", "property float y", "property float z",
      "property uchar red", "property uchar green", "property uchar blue",
      "property int num_observations"};
  EXPECT_EQ(header, expected);
  const std::string body((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_EQ(body.size(), 2u * 19u);
  for (size_t i = 0; i < points.size(); ++i) {
    const char* record = body.data() + 19 * i;
    float xyz[3];
    std::memcpy(xyz, record, 12);  // this test runs on little-endian hosts
    for (int k = 0; k < 3; ++k) EXPECT_FLOAT_EQ(xyz[k], static_cast<float>(points[i].point_in_world[k]));
    for (int k = 0; k < 3; ++k) EXPECT_EQ(static_cast<std::uint8_t>(record[12 + k]), points[i].rgb[k]);
    std::int32_t count;
    std::memcpy(&count, record + 15, 4);
    EXPECT_EQ(count, points[i].num_observations);
  }
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace omnirig::slam
