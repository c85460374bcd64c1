// The one PLY writer: header lines in order, packed little-endian body, optional properties.

#include "engine/geometry/ply.h"

#include <array>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <sstream>
#include <utility>
#include <vector>

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
  appender.Append(
      PlyCloud{whole.comment, {}, {}, true, {}, false, {}, false, {}});  // an empty part
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

// A reader of the header's declared properties, written apart from the writer: what a PLY
// consumer would see. Reads float, uchar and int properties of one vertex element.
PlyCloud ReadPly(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::string line;
  std::getline(in, line);
  EXPECT_EQ(line, "ply");
  std::getline(in, line);
  EXPECT_EQ(line, "format binary_little_endian 1.0");
  PlyCloud cloud;
  size_t count = 0;
  std::vector<std::pair<std::string, std::string>> properties;  // (type, name)
  while (std::getline(in, line) && line != "end_header") {
    std::istringstream words(line);
    std::string keyword, type, name;
    words >> keyword;
    if (keyword == "comment") cloud.comment = line.substr(8);
    if (keyword == "element") words >> name >> count;
    if (keyword == "property") {
      words >> type >> name;
      properties.emplace_back(type, name);
    }
  }
  for (const auto& [type, name] : properties) {
    cloud.has_confidence |= name == "confidence";
    cloud.has_range_std |= name == "range_std_m";
    cloud.has_num_observations |= name == "num_observations";
  }
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  size_t at = 0;
  const auto take = [&](size_t n, const char* what) {
    std::array<uint8_t, 4> value{};
    EXPECT_LE(at + n, bytes.size()) << what;
    for (size_t k = 0; k < n && at + k < bytes.size(); ++k) {
      value[k] = static_cast<uint8_t>(bytes[at + k]);
    }
    at += n;
    return value;
  };
  for (size_t i = 0; i < count; ++i) {
    Eigen::Vector3f position;
    std::array<uint8_t, 3> colour{};
    for (const auto& [type, name] : properties) {
      const std::array<uint8_t, 4> b = take(type == "uchar" ? 1 : 4, name.c_str());
      const uint32_t bits = b[0] | b[1] << 8 | b[2] << 16 | static_cast<uint32_t>(b[3]) << 24;
      float as_float;
      std::memcpy(&as_float, &bits, 4);
      if (name == "x" || name == "y" || name == "z") position[name[0] - 'x'] = as_float;
      if (name == "red" || name == "green" || name == "blue") {
        colour[name == "red" ? 0 : name == "green" ? 1 : 2] = b[0];
      }
      if (name == "confidence") cloud.confidence.push_back(as_float);
      if (name == "range_std_m") cloud.range_std_m.push_back(as_float);
      if (name == "num_observations") {
        cloud.num_observations.push_back(static_cast<int32_t>(bits));
      }
    }
    cloud.positions.push_back(position);
    cloud.colours.push_back(colour);
  }
  EXPECT_EQ(at, bytes.size()) << "bytes after the last vertex";
  return cloud;
}

// More vertices than the writer packs at once (65,536), so that its chunks' seams are read too.
PlyCloud RandomCloud(size_t count, bool with_confidence, bool with_observations,
                     bool with_range_std = false) {
  std::mt19937 random(7);
  std::uniform_real_distribution<float> coordinate(-50.f, 50.f), unit(0.f, 1.f);
  PlyCloud cloud;
  cloud.comment = "random, metres";
  cloud.has_confidence = with_confidence;
  cloud.has_num_observations = with_observations;
  cloud.has_range_std = with_range_std;
  for (size_t i = 0; i < count; ++i) {
    cloud.positions.emplace_back(coordinate(random), coordinate(random), coordinate(random));
    cloud.colours.push_back({static_cast<uint8_t>(random()), static_cast<uint8_t>(random()),
                             static_cast<uint8_t>(random())});
    if (with_confidence) cloud.confidence.push_back(unit(random));
    if (with_range_std) cloud.range_std_m.push_back(0.1f * unit(random));
    if (with_observations) cloud.num_observations.push_back(static_cast<int32_t>(random()));
  }
  return cloud;
}

void ExpectSameCloud(const PlyCloud& read, const PlyCloud& written) {
  EXPECT_EQ(read.comment, written.comment);
  EXPECT_EQ(read.has_confidence, written.has_confidence);
  EXPECT_EQ(read.has_range_std, written.has_range_std);
  EXPECT_EQ(read.has_num_observations, written.has_num_observations);
  ASSERT_EQ(read.size(), written.size());
  for (size_t i = 0; i < written.size(); ++i) {
    ASSERT_EQ(read.positions[i], written.positions[i]) << "vertex " << i;  // bit for bit
    ASSERT_EQ(read.colours[i], written.colours[i]) << "vertex " << i;
  }
  EXPECT_EQ(read.confidence, written.confidence);
  EXPECT_EQ(read.range_std_m, written.range_std_m);
  EXPECT_EQ(read.num_observations, written.num_observations);
}

TEST(Ply, WrittenCloudReadsBackIdentically) {
  const std::filesystem::path path = std::filesystem::temp_directory_path() /
                                     ("omnirig_ply_back_" + std::to_string(::getpid()) + ".ply");
  for (const auto& [confidence, observations] :
       std::vector<std::pair<bool, bool>>{{true, false}, {false, true}, {false, false}}) {
    const PlyCloud cloud = RandomCloud(150000, confidence, observations);
    WritePly(path, cloud);
    ExpectSameCloud(ReadPly(path), cloud);
  }
  // The dense clouds' properties: confidence and range std (and all three together).
  for (const bool observations : {false, true}) {
    const PlyCloud cloud = RandomCloud(150000, true, observations, true);
    WritePly(path, cloud);
    ExpectSameCloud(ReadPly(path), cloud);
  }
  // The appender's parts (one across a chunk's seam) read back as the whole.
  const PlyCloud whole = RandomCloud(100000, true, false);
  PlyAppender appender(path);
  for (const auto& [begin, end] :
       std::vector<std::pair<size_t, size_t>>{{0, 70000}, {70000, 100000}}) {
    PlyCloud part;
    part.comment = whole.comment;
    part.has_confidence = true;
    part.positions.assign(whole.positions.begin() + begin, whole.positions.begin() + end);
    part.colours.assign(whole.colours.begin() + begin, whole.colours.begin() + end);
    part.confidence.assign(whole.confidence.begin() + begin, whole.confidence.begin() + end);
    appender.Append(part);
  }
  appender.Finish();
  ExpectSameCloud(ReadPly(path), whole);
  std::filesystem::remove(path);
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
