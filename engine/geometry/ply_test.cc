// The one PLY writer: header lines in order, packed little-endian body, optional properties.

#include "engine/geometry/ply.h"

#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <gtest/gtest.h>
#include <unistd.h>

#include "engine/util/check.h"

namespace omnirig {
namespace {

std::string WriteAndRead(const PlyCloud& cloud) {
  const std::filesystem::path path = std::filesystem::temp_directory_path() /
                                     ("omnirig_ply_" + std::to_string(::getpid()) + ".ply");
  WritePly(path, cloud);
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  std::filesystem::remove(path);
  return buffer.str();
}

float ReadFloatLe(const std::string& data, size_t offset) {
  uint32_t bits = 0;
  for (int k = 0; k < 4; ++k)
    bits |= static_cast<uint32_t>(static_cast<uint8_t>(data[offset + k])) << (8 * k);
  float value;
  std::memcpy(&value, &bits, sizeof(value));
  return value;
}

PlyCloud TwoPoints() {
  PlyCloud cloud;
  cloud.comment = "test, metres";
  cloud.positions = {Eigen::Vector3f(1.5f, -2.25f, 3.0f), Eigen::Vector3f(0.0f, 0.5f, -1.0f)};
  cloud.colours = {{10, 20, 30}, {255, 0, 128}};
  return cloud;
}

TEST(Ply, ColouredPointsWithConfidence) {
  PlyCloud cloud = TwoPoints();
  cloud.has_confidence = true;
  cloud.confidence = {0.25f, 1.0f};
  const std::string data = WriteAndRead(cloud);
  const std::string end = "end_header\n";
  const size_t body = data.find(end);
  ASSERT_NE(body, std::string::npos);
  EXPECT_EQ(data.substr(0, body),
            "ply\nformat binary_little_endian 1.0\ncomment test, metres\nelement vertex 2\n"
            "property float x\nproperty float y\nproperty float z\nproperty uchar red\n"
            "property uchar green\nproperty uchar blue\nproperty float confidence\n");
  const size_t start = body + end.size();
  ASSERT_EQ(data.size() - start, 2u * 19u);
  EXPECT_EQ(ReadFloatLe(data, start), 1.5f);
  EXPECT_EQ(ReadFloatLe(data, start + 4), -2.25f);
  EXPECT_EQ(ReadFloatLe(data, start + 8), 3.0f);
  EXPECT_EQ(static_cast<uint8_t>(data[start + 12]), 10);
  EXPECT_EQ(static_cast<uint8_t>(data[start + 14]), 30);
  EXPECT_EQ(ReadFloatLe(data, start + 15), 0.25f);
  EXPECT_EQ(ReadFloatLe(data, start + 19 + 8), -1.0f);
  EXPECT_EQ(static_cast<uint8_t>(data[start + 19 + 12]), 255);
  EXPECT_EQ(ReadFloatLe(data, start + 19 + 15), 1.0f);
}

TEST(Ply, WithoutOptionalPropertiesIs15BytesPerVertex) {
  const std::string data = WriteAndRead(TwoPoints());
  const size_t body = data.find("end_header\n");
  ASSERT_NE(body, std::string::npos);
  EXPECT_EQ(data.find("confidence"), std::string::npos);
  EXPECT_EQ(data.size() - body - 11, 2u * 15u);
}

std::string ReadFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

TEST(Ply, AppenderWritesWhatOneWriteWould) {
  PlyCloud whole = TwoPoints();
  whole.has_confidence = true;
  whole.confidence = {0.25f, 1.0f};
  PlyCloud first = whole, second = whole;
  first.positions.pop_back();
  first.colours.pop_back();
  first.confidence.pop_back();
  second.positions.erase(second.positions.begin());
  second.colours.erase(second.colours.begin());
  second.confidence.erase(second.confidence.begin());
  const std::filesystem::path path = std::filesystem::temp_directory_path() /
                                     ("omnirig_ply_parts_" + std::to_string(::getpid()) + ".ply");
  PlyAppender appender(path);
  appender.Append(first);
  appender.Append(PlyCloud{whole.comment, {}, {}, true, {}, false, {}});  // an empty part
  appender.Append(second);
  EXPECT_EQ(appender.size(), 2u);
  appender.Finish();
  EXPECT_FALSE(std::filesystem::exists(path.string() + ".part"));
  EXPECT_EQ(ReadFile(path), WriteAndRead(whole));
  std::filesystem::remove(path);
  PlyAppender other(path);
  other.Append(first);
  EXPECT_THROW(other.Append(TwoPoints()), InvalidArgument);  // without confidence
  std::filesystem::remove(path.string() + ".part");
}

TEST(Ply, EmptyCloudDeclaresItsProperties) {
  PlyCloud cloud;
  cloud.has_confidence = true;
  const std::string data = WriteAndRead(cloud);
  EXPECT_NE(data.find("element vertex 0\n"), std::string::npos);
  EXPECT_NE(data.find("property float confidence\nend_header\n"), std::string::npos);
}

TEST(Ply, RejectsMismatchedLengths) {
  PlyCloud cloud = TwoPoints();
  cloud.has_confidence = true;
  cloud.confidence = {0.5f};
  EXPECT_THROW(cloud.Check(), InvalidArgument);
  cloud.has_confidence = false;  // values of an undeclared property
  cloud.confidence = {0.5f, 0.5f};
  EXPECT_THROW(cloud.Check(), InvalidArgument);
  cloud = TwoPoints();
  cloud.colours.pop_back();
  EXPECT_THROW(cloud.Check(), InvalidArgument);
}

}  // namespace
}  // namespace omnirig
