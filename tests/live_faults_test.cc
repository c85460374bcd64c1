// Live slam jobs through real processes: the server (this test binary re-executed with
// "--serve", its relative_pose job type answering with the rendered rig) is killed with SIGKILL
// during a live job and restarted; its data folder's disk fills up (a size-limited tmpfs; root
// only, skipped with the reason otherwise) while frames arrive; and the shipped `omnirig live`
// plays a rendered recording against it and prints its figures.

#include <gtest/gtest.h>
#include <signal.h>
#include <sys/mount.h>
#include <sys/statvfs.h>
#include <sys/wait.h>
#include <opencv2/imgcodecs.hpp>

#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <future>
#include <regex>
#include <sstream>

#include "api/camera_json.h"
#include "engine/slam/evaluation.h"
#include "engine/slam/map_io.h"
#include "engine/slam/video_source.h"
#include "server/commands.h"
#include "testing/slam/sequence_accuracy.h"
#include "tests/server_test_util.h"

namespace omnirig::testing {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

constexpr int64_t kMiB = 1 << 20;
constexpr int kNumFrames = 8;

std::string ReadFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream content;
  content << in.rdbuf();
  return content.str();
}

int64_t FreeBytes(const fs::path& path) {
  struct statvfs stats {};
  if (::statvfs(path.c_str(), &stats) != 0) return -1;
  return static_cast<int64_t>(stats.f_bavail) * static_cast<int64_t>(stats.f_frsize);
}

// The server's relative_pose job type in this binary: its result is the rig in the file
// $OMNIRIG_TEST_RIG_FILE (the render's calibration stands for a measured one).
api::JobType RenderedRigJobType() {
  api::JobType type;
  type.name = "relative_pose";
  type.validate = [](const json&) {};
  type.reads_images = false;
  type.run = [](const json&, const api::JobContext&) {
    const char* path = std::getenv("OMNIRIG_TEST_RIG_FILE");
    if (!path) throw std::runtime_error("OMNIRIG_TEST_RIG_FILE is not set");
    return json::parse(ReadFile(path));
  };
  return type;
}

class LiveFaultsTest : public ::testing::Test {
 protected:
  // The recording: cam0/ and cam1/ PNGs named by their stamps (0.1 s apart), the ground truth
  // beside them (trajectory.tum) and the rig's file for the server.
  static void SetUpTestSuite() {
    recording_ = new TempDir();
    const synth::StereoSequence sequence =
        synth::MakeStereoSequence(slam::ShortSequenceOptions(kNumFrames));
    std::vector<slam::StampedPose> truth;
    for (int i = 0; i < kNumFrames; ++i) {
      const std::string name = slam::FrameName(0.1 * i) + ".png";
      for (int c = 0; c < 2; ++c) {
        const fs::path path = Dir() / ("cam" + std::to_string(c)) / name;
        fs::create_directories(path.parent_path());
        std::vector<uchar> bytes;
        cv::imencode(".png", sequence.images[c][i], bytes);
        std::ofstream(path, std::ios::binary)
            .write(reinterpret_cast<const char*>(bytes.data()), bytes.size());
      }
      truth.push_back({0.1 * i, sequence.world_from_rig[i]});
    }
    slam::WriteTum(Dir() / "trajectory.tum", truth);
    std::ofstream(recording_->path() / "rig.json") << api::RigToJson(sequence.rig).dump();
    ::setenv("OMNIRIG_TEST_RIG_FILE", (recording_->path() / "rig.json").c_str(), 1);
  }
  static void TearDownTestSuite() { delete recording_; }
  static fs::path Dir() { return recording_->path() / "recording"; }

  void TearDown() override {
    client_.reset();
    if (server_) {
      server_->Kill(SIGTERM);
      EXPECT_EQ(server_->Wait(), 0);
      server_.reset();
    }
    if (mounted_) ::umount2(disk_.c_str(), MNT_DETACH);
  }

  void StartServer(const fs::path& data, const std::vector<std::string>& more = {}) {
    std::vector<std::string> args = {"--port", "0",     "--data", data.string(),       "--workers",
                                     "1",      "--web", "",       "--threads-per-job", "1"};
    args.insert(args.end(), more.begin(), more.end());
    server_ = std::make_unique<ServerProcess>();
    port_ = server_->Start(args, dir_.path() / "server.log");
    client_ = MakeClient(port_);
  }

  // A succeeded relative_pose job (the rendered rig).
  std::string SubmitRig() {
    const json dataset =
        JsonOf(client_->Post("/api/v1/datasets", json{{"name", "rig"}}.dump(), "application/json"));
    const auto created = client_->Post(
        "/api/v1/jobs", json{{"type", "relative_pose"}, {"dataset", dataset["id"]}}.dump(),
        "application/json");
    EXPECT_EQ(created->status, 202) << created->body;
    const std::string id = JsonOf(created)["id"];
    EXPECT_EQ(WaitForJob(port_, id, 60)["state"], "succeeded");
    return id;
  }

  json CreateLive(const std::string& rig) {
    const auto created = client_->Post(
        "/api/v1/jobs",
        json{{"type", "slam"}, {"dataset", ""}, {"params", {{"rig", rig}, {"live", true}}}}.dump(),
        "application/json");
    EXPECT_EQ(created->status, 202) << created->body;
    return JsonOf(created);
  }

  static httplib::Result PostFrame(httplib::Client& client, const std::string& job, int i) {
    const std::string name = slam::FrameName(0.1 * i) + ".png";
    const httplib::MultipartFormDataItems items = {
        {"cam0", ReadFile(Dir() / "cam0" / name), "cam0.png", "image/png"},
        {"cam1", ReadFile(Dir() / "cam1" / name), "cam1.png", "image/png"},
        {"stamp", std::to_string(0.1 * i), "", ""}};
    return client.Post(("/api/v1/jobs/" + job + "/frames").c_str(), items);
  }

  json Dataset(const std::string& id) {
    return JsonOf(client_->Get(("/api/v1/datasets/" + id).c_str()));
  }

  static TempDir* recording_;
  TempDir dir_;
  std::unique_ptr<ServerProcess> server_;
  std::unique_ptr<httplib::Client> client_;
  int port_ = 0;
  fs::path disk_;
  bool mounted_ = false;
};

TempDir* LiveFaultsTest::recording_ = nullptr;

TEST_F(LiveFaultsTest, AKilledServersLiveJobRunsAgainAsABatchJobOverEveryStoredFrame) {
  const fs::path data = dir_.path() / "data";
  StartServer(data);
  const std::string rig = SubmitRig();
  const json job = CreateLive(rig);
  const std::string id = job["id"], dataset = job["dataset"];
  for (int i = 0; i < 4; ++i) ASSERT_EQ(PostFrame(*client_, id, i)->status, 200);
  // A fifth frame in flight: stored, its pose perhaps not yet answered, when the server dies.
  std::future<void> in_flight = std::async(std::launch::async, [&] {
    auto client = MakeClient(port_);
    PostFrame(*client, id, 4);  // no answer: the server is killed
  });
  while (Dataset(dataset)["image_count"] < 2 * 5) std::this_thread::yield();
  server_->Kill(SIGKILL);
  EXPECT_EQ(server_->Wait(), 128 + SIGKILL);
  in_flight.get();

  // The next server on the same folder runs the job again, as a batch job over its dataset.
  StartServer(data);
  const json rerun = WaitForJob(port_, id, 240);
  ASSERT_EQ(rerun["state"], "succeeded") << rerun.dump();
  const json images = Dataset(dataset)["images"];
  ASSERT_EQ(images.size(), 2u * 5) << images.dump();
  const json result = JsonOf(client_->Get(("/api/v1/jobs/" + id + "/result").c_str()));
  EXPECT_FALSE(result.contains("live"));  // a batch run
  ASSERT_EQ(result["num_frames"], 5) << result.dump();
  EXPECT_EQ(result["num_tracked"], 5);
  const json trajectory =
      JsonOf(client_->Get(("/api/v1/jobs/" + id + "/artifacts/trajectory.json").c_str()));
  ASSERT_EQ(trajectory["frames"].size(), 5u);
  for (int i = 0; i < 5; ++i) {
    EXPECT_EQ(trajectory["frames"][i]["name"], slam::FrameName(0.1 * i) + ".png");
    EXPECT_TRUE(trajectory["frames"][i]["world_from_rig"].is_object()) << i;
  }
  // Frames to it now: it is no live job any more.
  EXPECT_EQ(PostFrame(*client_, id, 5)->status, 409);
}

TEST_F(LiveFaultsTest, FramesOnAFullDiskAre507AndTheJobGoesOnWhenSpaceReturns) {
  disk_ = dir_.path() / "disk";
  fs::create_directories(disk_);
  if (::mount("tmpfs", disk_.c_str(), "tmpfs", 0, "size=32m") != 0) {
    GTEST_SKIP() << "cannot mount a 32 MB tmpfs at " << disk_ << " (" << std::strerror(errno)
                 << "): the full-disk test needs root (CAP_SYS_ADMIN), as CI has";
  }
  mounted_ = true;
  const fs::path data = disk_ / "data";
  StartServer(data, {"--min-free-mb", "4"});
  const std::string rig = SubmitRig();
  const json job = CreateLive(rig);
  const std::string id = job["id"], dataset = job["dataset"];
  for (int i = 0; i < 2; ++i) ASSERT_EQ(PostFrame(*client_, id, i)->status, 200);

  // The disk fills (a file outside the data folder): free space above the 4 MB reserve is less
  // than the next frame.
  const std::string name = slam::FrameName(0.2) + ".png";
  const int64_t frame_bytes = static_cast<int64_t>(ReadFile(Dir() / "cam0" / name).size() +
                                                   ReadFile(Dir() / "cam1" / name).size());
  {
    const int64_t fill = FreeBytes(disk_) - 4 * kMiB - frame_bytes / 2;
    ASSERT_GT(fill, 0);
    std::ofstream filler(disk_ / "filler", std::ios::binary);
    const std::string block(kMiB, 'x');
    for (int64_t written = 0; written < fill; written += kMiB) {
      filler.write(block.data(), std::min<int64_t>(kMiB, fill - written));
    }
    filler.close();
    ASSERT_TRUE(filler) << "cannot write the filler file";
  }
  for (int attempt = 0; attempt < 2; ++attempt) {
    const auto refused = PostFrame(*client_, id, 2);
    ASSERT_TRUE(refused);
    ASSERT_EQ(refused->status, 507) << refused->body;
    const json error = JsonOf(refused)["error"];
    EXPECT_EQ(error["code"], "insufficient_storage") << refused->body;
    EXPECT_FALSE(error["message"].get<std::string>().empty());
    EXPECT_EQ(error["details"]["reserve_bytes"], 4 * kMiB);
  }
  // Nothing partial: the dataset holds the two frames, its folder their four files.
  EXPECT_EQ(Dataset(dataset)["image_count"], 4);
  int files = 0;
  for (const auto& entry : fs::recursive_directory_iterator(data / "datasets" / dataset)) {
    files += entry.is_regular_file();
  }
  EXPECT_EQ(files, 4);
  EXPECT_EQ(JsonOf(client_->Get(("/api/v1/jobs/" + id).c_str()))["state"], "running");

  // Space returns: the refused frame is sent again and tracked, the job goes on to the end.
  fs::remove(disk_ / "filler");
  for (int i = 2; i < 4; ++i) {
    const auto answer = PostFrame(*client_, id, i);
    ASSERT_EQ(answer->status, 200) << answer->body;
    EXPECT_EQ(JsonOf(answer)["frame_index"], i);
    EXPECT_EQ(JsonOf(answer)["state"], "tracked");
  }
  ASSERT_EQ(client_->Post(("/api/v1/jobs/" + id + "/finish").c_str())->status, 202);
  const json done = WaitForJob(port_, id, 240);
  ASSERT_EQ(done["state"], "succeeded") << done.dump();
  const json result = JsonOf(client_->Get(("/api/v1/jobs/" + id + "/result").c_str()));
  EXPECT_EQ(result["num_frames"], 4);
  EXPECT_EQ(result["live"]["num_skipped"], 0);
  EXPECT_EQ(Dataset(dataset)["image_count"], 8);
}

// The job takes a frame as the server starts storing it: a frame whose files are written but
// cannot be recorded (the dataset is full) is refused, and the job, which already had it, does
// not track it.
TEST_F(LiveFaultsTest, AFrameThatCannotBeStoredIsNotTracked) {
  StartServer(dir_.path() / "data", {"--max-images", "6"});
  const std::string rig = SubmitRig();
  const json job = CreateLive(rig);
  const std::string id = job["id"], dataset = job["dataset"];
  for (int i = 0; i < 3; ++i) {
    const auto answer = PostFrame(*client_, id, i);
    ASSERT_EQ(answer->status, 200) << answer->body;
    EXPECT_EQ(JsonOf(answer)["frame_index"], i);
  }
  for (int attempt = 0; attempt < 2; ++attempt) {
    const auto refused = PostFrame(*client_, id, 3);
    ASSERT_TRUE(refused);
    ASSERT_EQ(refused->status, 413) << refused->body;
    EXPECT_EQ(JsonOf(refused)["error"]["code"], "too_many_images") << refused->body;
  }
  EXPECT_EQ(Dataset(dataset)["image_count"], 6);
  ASSERT_EQ(client_->Post(("/api/v1/jobs/" + id + "/finish").c_str())->status, 202);
  const json done = WaitForJob(port_, id, 240);
  ASSERT_EQ(done["state"], "succeeded") << done.dump();
  const json result = JsonOf(client_->Get(("/api/v1/jobs/" + id + "/result").c_str()));
  EXPECT_EQ(result["num_frames"], 3) << result.dump();
  EXPECT_EQ(result["live"]["num_tracked_frames"], 3);
  EXPECT_EQ(result["live"]["num_skipped"], 0);
  const json trajectory =
      JsonOf(client_->Get(("/api/v1/jobs/" + id + "/artifacts/trajectory.json").c_str()));
  ASSERT_EQ(trajectory["frames"].size(), 3u) << trajectory.dump();
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(trajectory["frames"][i]["name"], slam::FrameName(0.1 * i) + ".png");
  }
}

// The number `omnirig live` printed in the first group of `pattern`.
double Figure(const std::string& text, const std::string& pattern) {
  std::smatch match;
  if (!std::regex_search(text, match, std::regex(pattern))) {
    ADD_FAILURE() << "no '" << pattern << "' in:\n" << text;
    return -1;
  }
  return std::stod(match[1]);
}

TEST_F(LiveFaultsTest, OmnirigLivePlaysARecordingAndPrintsItsFigures) {
  const char* binary_dir = std::getenv("OMNIRIG_BINARY_DIR");
  if (!binary_dir) GTEST_SKIP() << "OMNIRIG_BINARY_DIR not set (run through ctest)";
  StartServer(dir_.path() / "data");
  const std::string rig = SubmitRig();
  const fs::path out = dir_.path() / "live.out", figures = dir_.path() / "live.json";
  const std::string command = (fs::path(binary_dir) / "server" / "omnirig").string() +
                              " live --server http://127.0.0.1:" + std::to_string(port_) +
                              " --rig " + rig + " --json " + figures.string() + " " +
                              Dir().string() + " > " + out.string() + " 2> " +
                              (dir_.path() / "live.err").string();
  const int status = std::system(command.c_str());
  const std::string text = ReadFile(out);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0)
      << text << ReadFile(dir_.path() / "live.err");

  // What it printed is what the server measured: the job's result holds the same frames, the
  // same latencies (receipt to pose) and the same skipped frames.
  const json summary = json::parse(ReadFile(figures));
  const std::string id = summary["job"];
  const json result = JsonOf(client_->Get(("/api/v1/jobs/" + id + "/result").c_str()));
  const int tracked = static_cast<int>(
      Figure(text, "succeeded: (\\d+) of " + std::to_string(kNumFrames) + " frames tracked"));
  const int skipped = static_cast<int>(Figure(text, "frames tracked, (\\d+) skipped"));
  EXPECT_EQ(tracked + skipped, kNumFrames) << text;
  EXPECT_GE(tracked, 2) << text;  // the first frame and the last are always sent
  EXPECT_EQ(result["num_frames"], tracked);
  EXPECT_LE(result["live"]["num_skipped"].get<int>(), skipped);  // the client skips the others
  EXPECT_EQ(summary["frames_tracked"], tracked);
  EXPECT_EQ(summary["frames_skipped"], skipped);
  for (const char* p : {"p50", "p95", "p99"}) {
    const double printed = Figure(text, std::string(p) + " ([0-9.]+)");
    EXPECT_NEAR(printed, result["live"]["latency_ms"][p].get<double>(), 0.051) << p << "\n" << text;
    EXPECT_GT(printed, 0.0);
  }
  EXPECT_LE(Figure(text, "p50 ([0-9.]+)"), Figure(text, "p95 ([0-9.]+)"));

  // The ATE against the recording's ground truth, from the finished job's trajectory.
  const double ate_m = Figure(text, "ATE ([0-9.]+) m");
  EXPECT_NEAR(ate_m, summary["evaluation"]["ate_rmse_m"].get<double>(), 1e-4);
  EXPECT_EQ(summary["evaluation"]["num_poses"], tracked);
  const json trajectory =
      JsonOf(client_->Get(("/api/v1/jobs/" + id + "/artifacts/trajectory.json").c_str()));
  const std::vector<slam::StampedPose> truth = slam::ReadTum(Dir() / "trajectory.tum");
  std::vector<Rigid3d> estimate, matched;
  for (const json& frame : trajectory["frames"]) {
    const std::string stem = fs::path(frame["name"].get<std::string>()).stem().string();
    for (const slam::StampedPose& pose : truth) {
      if (slam::FrameName(pose.timestamp_s) == stem) {
        estimate.push_back(api::PoseFromJson(frame["world_from_rig"]));
        matched.push_back(pose.world_from_rig);
      }
    }
  }
  ASSERT_EQ(static_cast<int>(estimate.size()), tracked);
  const slam::TrajectoryErrors errors = slam::EvaluateTrajectory(estimate, matched);
  EXPECT_NEAR(ate_m, errors.ate_rmse_m, 1e-4);
  EXPECT_LT(ate_m, 0.03);  // a rendered sequence with an exact rig: 3 cm, as tracking each frame

  // Played again with --map: localised in the first run's saved map, and says how much of it;
  // this time each frame posted as it is captured, up to 3 outstanding (the server skips).
  const fs::path again = dir_.path() / "again.out", again_figures = dir_.path() / "again.json";
  const std::string with_map = (fs::path(binary_dir) / "server" / "omnirig").string() +
                               " live --server http://127.0.0.1:" + std::to_string(port_) +
                               " --rig " + rig + " --map " + id + " --in-flight 3 --json " +
                               again_figures.string() + " " + Dir().string() + " > " +
                               again.string() + " 2> " + (dir_.path() / "again.err").string();
  const int again_status = std::system(with_map.c_str());
  const std::string again_text = ReadFile(again);
  ASSERT_TRUE(WIFEXITED(again_status) && WEXITSTATUS(again_status) == 0)
      << again_text << ReadFile(dir_.path() / "again.err");
  const json again_summary = json::parse(ReadFile(again_figures));
  const json again_result = JsonOf(client_->Get(
      ("/api/v1/jobs/" + again_summary["job"].get<std::string>() + "/result").c_str()));
  EXPECT_EQ(again_result["saved_map"]["localised_in"], id);
  // Every frame answered: tracked, or skipped by the server or the client; none refused.
  EXPECT_EQ(again_summary["in_flight"], 3);
  EXPECT_EQ(again_summary["frames_refused"], 0) << again_text;
  EXPECT_EQ(again_summary["frames_tracked"].get<int>() + again_summary["frames_skipped"].get<int>(),
            kNumFrames)
      << again_text;
  EXPECT_EQ(again_result["num_frames"], again_summary["frames_tracked"]);
  EXPECT_LE(again_result["live"]["num_skipped"].get<int>(),
            again_summary["frames_skipped"].get<int>());
  EXPECT_GT(Figure(again_text, "capture to pose ms .* p50 ([0-9.]+)"), 0.0) << again_text;
  const double fraction = again_result["localised_in_map_fraction"].get<double>();
  EXPECT_NEAR(Figure(again_text, "in map ([0-9.]+) % of the frames tracked"), 100 * fraction, 0.051)
      << again_text;
  EXPECT_GE(fraction, 0.95) << again_text;  // the same places, the same light
}

}  // namespace
}  // namespace omnirig::testing

int main(int argc, char** argv) {
  if (argc >= 2 && std::string(argv[1]) == "--serve") {
    return omnirig::server::ServeCommand(
        std::vector<std::string>(argv + 2, argv + argc),
        {omnirig::testing::SleepJobType(), omnirig::testing::RenderedRigJobType()});
  }
  signal(SIGPIPE, SIG_IGN);
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
