// The saved map's file (saved_map.cc): what is written reads back the same, and a file of
// another version, another kind or cut short is refused with a clear error.

#include "engine/slam/saved_map.h"

#include <cstring>
#include <filesystem>
#include <fstream>

#include <gtest/gtest.h>

#include "engine/util/check.h"

namespace omnirig::slam {
namespace {

SavedMap SmallMap() {
  SavedMap map;
  for (int k = 0; k < 2; ++k) {
    SavedKeyframe& keyframe = map.keyframes.emplace_back();
    keyframe.name = "frame_00" + std::to_string(k);
    keyframe.rig_from_world =
        Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(0.1 * k, Eigen::Vector3d::UnitZ())),
                Eigen::Vector3d(0.5 * k, -0.25, 1.0));
    keyframe.path_m = 0.5 * k;
    for (int f = 0; f < 3; ++f) {
      keyframe.cam0.pixels.emplace_back(100.0 + f, 200.5 - f);
      keyframe.cam0.bearings.push_back(Eigen::Vector3d(0.1 * f, 0.2, 1.0).normalized());
      keyframe.cam0.rgb.push_back({static_cast<std::uint8_t>(f), 7, 200});
    }
    keyframe.cam0.descriptors = cv::Mat(3, 128, CV_8U);
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 128; ++c)
        keyframe.cam0.descriptors.at<std::uint8_t>(r, c) = (r * 31 + c + k) % 256;
    }
    keyframe.num_cam1_features = 2;
    keyframe.landmark_of[0] = {0, -1, 1};
    keyframe.landmark_of[1] = {-1, 0};
    StereoPoint& point = keyframe.stereo.emplace_back();
    point.feature0 = 0;
    point.feature1 = 1;
    point.point_in_cam0 = Eigen::Vector3d(1.0, 2.0, 3.0);
    point.range_std_m = 0.01;
  }
  for (int l = 0; l < 2; ++l) {
    Landmark& landmark = map.landmarks.emplace_back();
    landmark.point_in_world = Eigen::Vector3d(l, 2.0, -1.0);
    landmark.rgb = {10, 20, 30};
    landmark.observations.push_back({0, 0, l == 0 ? 0 : 2, Eigen::Vector2d(100.0, 200.5)});
    landmark.observations.push_back({1, 0, l == 0 ? 0 : 2, Eigen::Vector2d(101.0, 199.5)});
  }
  map.landmarks[0].observations.push_back({0, 1, 1, Eigen::Vector2d(50.0, 60.0)});
  return map;
}

std::string ErrorOf(const std::vector<std::uint8_t>& bytes) {
  try {
    DeserializeSavedMap(bytes.data(), bytes.size());
  } catch (const InvalidArgument& e) {
    return e.what();
  }
  return "";
}

TEST(SavedMap, ReadsBackWhatWasWritten) {
  const SavedMap map = SmallMap();
  const std::filesystem::path path =
      std::filesystem::path(::testing::TempDir()) / "saved_map_test.bin";
  WriteSavedMap(path, map);
  const SavedMap read = ReadSavedMap(path);
  ASSERT_EQ(read.keyframes.size(), 2u);
  ASSERT_EQ(read.landmarks.size(), 2u);
  EXPECT_EQ(read.keyframes[1].name, "frame_001");
  EXPECT_TRUE(read.keyframes[1].rig_from_world.translation.isApprox(
      map.keyframes[1].rig_from_world.translation));
  EXPECT_EQ(read.keyframes[1].landmark_of[0], map.keyframes[1].landmark_of[0]);
  EXPECT_EQ(read.keyframes[1].landmark_of[1], map.keyframes[1].landmark_of[1]);
  EXPECT_EQ(
      cv::norm(read.keyframes[1].cam0.descriptors, map.keyframes[1].cam0.descriptors, cv::NORM_L1),
      0.0);
  EXPECT_EQ(read.keyframes[0].stereo[0].pixel0, map.keyframes[0].cam0.pixels[0]);
  EXPECT_EQ(read.landmarks[0].observations.size(), 3u);
  // The same bytes again: nothing is lost or rounded on the way.
  EXPECT_EQ(SerializeSavedMap(read), SerializeSavedMap(map));
  std::filesystem::remove(path);
}

TEST(SavedMap, RefusesAnotherVersionAnotherKindAndATruncatedFile) {
  const std::vector<std::uint8_t> bytes = SerializeSavedMap(SmallMap());
  std::vector<std::uint8_t> newer = bytes;
  const std::uint32_t version = kSavedMapVersion + 1;
  std::memcpy(newer.data() + 12, &version, 4);
  EXPECT_NE(ErrorOf(newer).find("format version 2 is not one this omnirig reads"),
            std::string::npos)
      << ErrorOf(newer);
  const std::vector<std::uint8_t> ply = {'p', 'l', 'y', '\n', 'f', 'o', 'r', 'm',
                                         'a', 't', ' ', 'b',  0,   0,   0,   0};
  EXPECT_NE(ErrorOf(ply).find("not an omnirig saved map"), std::string::npos);
  // Every cut is refused (never read past the end).
  for (size_t size = 0; size < bytes.size(); size += 7) {
    const std::vector<std::uint8_t> cut(bytes.begin(), bytes.begin() + size);
    EXPECT_FALSE(ErrorOf(cut).empty()) << size;
  }
  // A landmark index out of range.
  SavedMap bad = SmallMap();
  bad.keyframes[0].landmark_of[0][1] = 5;
  EXPECT_NE(ErrorOf(SerializeSavedMap(bad)).find("unknown landmark"), std::string::npos);
}

TEST(SavedMap, ReadErrorsNameTheFile) {
  const std::filesystem::path path = std::filesystem::path(::testing::TempDir()) / "not_a_map.bin";
  std::ofstream(path) << "hello";
  try {
    ReadSavedMap(path);
    FAIL() << "read a text file as a map";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("not_a_map.bin"), std::string::npos) << e.what();
  }
  std::filesystem::remove(path);
}

}  // namespace
}  // namespace omnirig::slam
