// The live job's publisher (api/live_publisher.h): the snapshot handed over is written by its
// own thread and told of; a write that fails is logged and done again an interval later without
// a new snapshot; a keyframe whose images cannot be read back is logged and the grid goes on;
// Stop() joins and may be called again. The occupancy grid from real keyframes is tested through
// the server (tests/server_live_test.cc).

#include "api/live_publisher.h"

#include <condition_variable>
#include <fstream>
#include <mutex>

#include <gtest/gtest.h>
#include <unistd.h>

#include "testing/geometry/test_rig.h"

namespace omnirig::api {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

// What the publisher's threads told: log lines and refreshes, waited for without a clock.
class Told {
 public:
  void Line(const std::string& line) {
    std::lock_guard<std::mutex> lock(mutex_);
    lines_.push_back(line);
    changed_.notify_all();
  }
  void Refreshed(const json& refreshed) {
    std::lock_guard<std::mutex> lock(mutex_);
    refreshed_.push_back(refreshed);
    changed_.notify_all();
  }
  // Waits for a log line containing `text`.
  void WaitForLine(const std::string& text) {
    std::unique_lock<std::mutex> lock(mutex_);
    changed_.wait(lock, [&] {
      for (const std::string& line : lines_) {
        if (line.find(text) != std::string::npos) return true;
      }
      return false;
    });
  }
  json WaitForRefresh() {
    std::unique_lock<std::mutex> lock(mutex_);
    changed_.wait(lock, [&] { return !refreshed_.empty(); });
    return refreshed_.front();
  }
  size_t num_lines() {
    std::lock_guard<std::mutex> lock(mutex_);
    return lines_.size();
  }

 private:
  std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<std::string> lines_;
  std::vector<json> refreshed_;
};

std::shared_ptr<const LiveSnapshot> TwoFrames() {
  auto snapshot = std::make_shared<LiveSnapshot>();
  snapshot->slam.names = {"t000000.000.png", "t000000.100.png"};
  snapshot->slam.states = {"initialised", "tracked"};
  snapshot->slam.world_from_rig = {
      Rigid3d(), Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.5, 0, 0))};
  snapshot->slam.keyframes = {0, 1};
  snapshot->slam.num_keyframes = 2;
  slam::MapPoint point;
  point.point_in_world = Eigen::Vector3d(1, 2, 3);
  snapshot->slam.map = {point};
  snapshot->stamps_s = {0.0, 0.1};
  return snapshot;
}

class LivePublisherTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("omnirig_live_publisher_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  LivePublisherOptions Options(const fs::path& output_dir) {
    LivePublisherOptions options;
    options.output_dir = output_dir;
    options.dataset_dir = dir_ / "dataset";
    options.interval_s = 0.01;
    options.log = [this](const std::string& line) { told_.Line(line); };
    options.on_artifacts = [this](const json& refreshed) { told_.Refreshed(refreshed); };
    return options;
  }

  fs::path dir_;
  Told told_;
};

TEST_F(LivePublisherTest, WritesTheSnapshotOnItsThreadAndTellsOfIt) {
  LivePublisher publisher(TinyTestRig(64, 48), Options(dir_));
  publisher.Publish(TwoFrames());
  const json refreshed = told_.WaitForRefresh();
  EXPECT_EQ(refreshed["artifacts"], json({"trajectory.json", "map.ply"}));
  EXPECT_EQ(refreshed["num_frames"], 2);
  const json trajectory = json::parse(std::ifstream(dir_ / "trajectory.json"));
  EXPECT_EQ(trajectory["live"], true);
  ASSERT_EQ(trajectory["frames"].size(), 2u);
  EXPECT_EQ(trajectory["frames"][1]["name"], "t000000.100.png");
  EXPECT_DOUBLE_EQ(trajectory["frames"][1]["world_from_rig"]["translation_m"][0].get<double>(),
                   0.5);
  std::ifstream ply(dir_ / "map.ply", std::ios::binary);
  std::string magic;
  ply >> magic;
  EXPECT_EQ(magic, "ply");
  publisher.Stop();
  publisher.Stop();  // again: nothing
  for (const auto& entry : fs::directory_iterator(dir_)) {
    EXPECT_EQ(entry.path().string().find(".part-live"), std::string::npos) << entry.path();
  }
}

TEST_F(LivePublisherTest, AFailedWriteIsLoggedAndDoneAgainWithoutANewSnapshot) {
  // A file where the output folder should be: as on a full disk, nothing can be written.
  const fs::path output = dir_ / "later";
  std::ofstream(output) << "in the way";
  LivePublisher publisher(TinyTestRig(64, 48), Options(output));
  publisher.Publish(TwoFrames());
  told_.WaitForLine("the map and trajectory so far cannot be written");
  // Space returns: the same snapshot is written an interval later.
  fs::remove(output);
  fs::create_directories(output);
  EXPECT_EQ(told_.WaitForRefresh()["num_frames"], 2);
  EXPECT_TRUE(fs::exists(output / "trajectory.json"));
  EXPECT_TRUE(fs::exists(output / "map.ply"));
}

TEST_F(LivePublisherTest, AKeyframeWhoseImagesAreMissingIsLoggedAndTheGridGoesOn) {
  LivePublisherOptions options = Options(dir_);
  options.dense_map = dense::DenseMapOptions();
  options.dense_map->keyframe_spacing_m = 0.25;
  LivePublisher publisher(TinyTestRig(64, 48), std::move(options));
  publisher.Publish(TwoFrames());
  // Both keyframes (0.5 m apart) are tried, in order; the dataset holds neither.
  told_.WaitForLine("keyframe t000000.000.png is not in the occupancy grid so far");
  told_.WaitForLine("keyframe t000000.100.png is not in the occupancy grid so far");
  EXPECT_EQ(publisher.num_fused_keyframes(), 0);
  publisher.Stop();
  EXPECT_FALSE(fs::exists(dir_ / "occupancy.pgm"));
}

}  // namespace
}  // namespace omnirig::api
