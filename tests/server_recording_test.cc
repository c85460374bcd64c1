// Robot recordings through the real service: ROS 1 bags, MCAP files and ROS 2 bags (a folder's
// files, or one .tar) written by independent writers (testing/recordings/), uploaded in
// resumable chunks or whole over a real HTTP server; the dataset's JSON lists each recording's
// topics; truncated and damaged recordings are refused with 422 corrupt_recording.

#include <gtest/gtest.h>

#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "api/camera_json.h"
#include "api/synth_json.h"
#include "engine/synth/presets.h"
#include "server/service.h"
#include "testing/recordings/test_recordings.h"
#include "tests/server_test_util.h"

namespace omnirig::testing {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr int64_t kChunk = 64 << 10;  // the server's max_chunk_bytes (its least)

std::string ReadFile(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return bytes.str();
}

std::string Written(const std::string& name) { return ReadFile(TestRecordingsDir() / name); }

double ReceivedS(int frame) {
  return static_cast<double>(kRecordingStartS) +
         (frame * kRecordingPeriodNs + kRecordingReceiveDelayNs) * 1e-9;
}

class ServerRecordingTest : public ::testing::Test {
 protected:
  void SetUp() override {
    server::ServiceOptions options;
    options.host = "127.0.0.1";
    options.port = 0;
    options.data_dir = dir_.path() / "data";
    options.workers.num_workers = 1;
    options.workers.threads_per_job = 1;
    options.min_free_bytes = 0;
    options.max_chunk_bytes = kChunk;
    service_ = std::make_unique<server::Service>(options);
    port_ = service_->Start();
    client_ = MakeClient(port_);
    const auto created =
        client_->Post("/api/v1/datasets", json{{"name", "robot"}}.dump(), "application/json");
    ASSERT_EQ(created->status, 201);
    dataset_ = JsonOf(created)["id"];
  }

  std::string Url(const std::string& name) const {
    return "/api/v1/datasets/" + dataset_ + "/images/" + name;
  }

  // Uploads `file` in chunks of kChunk (PUT with Content-Range); returns the last answer.
  httplib::Result UploadInChunks(const std::string& name, const std::string& file) {
    const int64_t total = static_cast<int64_t>(file.size());
    for (int64_t at = 0;;) {
      const int64_t size = std::min(kChunk, total - at);
      const std::string range = "bytes " + std::to_string(at) + "-" +
                                std::to_string(at + size - 1) + "/" + std::to_string(total);
      httplib::Result result = client_->Put(Url(name).c_str(), {{"Content-Range", range}},
                                            file.substr(at, size), "application/octet-stream");
      at += size;
      if (at >= total || !result || result->status != 202) return result;
    }
  }

  httplib::Result PutWhole(const std::string& name, const std::string& file) {
    return client_->Put(Url(name).c_str(), file, "application/octet-stream");
  }

  json Dataset() {
    const auto result = client_->Get(("/api/v1/datasets/" + dataset_).c_str());
    EXPECT_EQ(result->status, 200);
    return JsonOf(result);
  }

  json Recording(const std::string& name) {
    const json dataset = Dataset();
    for (const auto& recording : dataset["recordings"]) {
      if (recording["name"] == name) return recording;
    }
    ADD_FAILURE() << "the dataset lists no recording " << name << ": " << dataset.dump();
    return json::object();
  }

  void ExpectCorrupt(const httplib::Result& result, const std::string& name,
                     const std::string& words) {
    ASSERT_TRUE(result);
    EXPECT_EQ(result->status, 422) << result->body;
    const json body = JsonOf(result);
    EXPECT_EQ(body["error"]["code"], "corrupt_recording") << result->body;
    EXPECT_EQ(body["error"]["details"]["name"], name) << result->body;
    EXPECT_NE(body["error"]["message"].get<std::string>().find(words), std::string::npos)
        << result->body;
    EXPECT_EQ(client_->Get(Url(name).c_str())->status, 404) << "a refused file was stored";
  }

  TempDir dir_;
  std::unique_ptr<server::Service> service_;
  std::unique_ptr<httplib::Client> client_;
  std::string dataset_;
  int port_ = 0;
};

void ExpectImageTopic(const json& recording, const std::string& topic, const std::string& type) {
  for (const auto& listed : recording["topics"]) {
    if (listed["name"] != topic) continue;
    EXPECT_EQ(listed["type"], type);
    EXPECT_EQ(listed["message_count"], kRecordingFrames);
    EXPECT_NEAR(listed["first_stamp_s"].get<double>(), ReceivedS(0), 1e-6);
    EXPECT_NEAR(listed["last_stamp_s"].get<double>(), ReceivedS(kRecordingFrames - 1), 1e-6);
    EXPECT_NEAR(listed["rate_hz"].get<double>(), 20.0, 1e-6);
    return;
  }
  ADD_FAILURE() << recording.dump() << " lists no topic " << topic;
}

TEST_F(ServerRecordingTest, RecordingsGoUpInChunksAndListTheirTopics) {
  const std::string bag = Written("images_none.bag");
  ASSERT_GT(bag.size(), static_cast<size_t>(kChunk));  // more than one chunk
  const auto stored = UploadInChunks("run.bag", bag);
  ASSERT_EQ(stored->status, 201) << stored->body;
  EXPECT_EQ(JsonOf(stored)["content_type"], "application/x-rosbag");
  EXPECT_EQ(client_->Get(Url("run.bag").c_str())->body, bag);

  ASSERT_EQ(UploadInChunks("run_zstd.mcap", Written("images_zstd.mcap"))->status, 201);
  ASSERT_EQ(PutWhole("bare.mcap", Written("images_bare.mcap"))->status, 201);
  ASSERT_EQ(UploadInChunks("ros2.tar", Written("ros2_db3.tar"))->status, 201);

  const json dataset = Dataset();
  EXPECT_EQ(dataset["image_count"], 0) << "recordings take no place among the images";
  ASSERT_EQ(dataset["recordings"].size(), 4u) << dataset.dump();
  const json ros1 = Recording("run.bag");
  EXPECT_EQ(ros1["format"], "rosbag1");
  EXPECT_EQ(ros1["cut_short"], false);
  EXPECT_EQ(ros1["topics"].size(), 5u);
  ExpectImageTopic(ros1, "/cam0/image_raw", "sensor_msgs/Image");
  ExpectImageTopic(ros1, "/cam0/image_raw/compressed", "sensor_msgs/CompressedImage");
  for (const std::string name : {"run_zstd.mcap", "bare.mcap"}) {
    const json mcap = Recording(name);
    EXPECT_EQ(mcap["format"], "mcap");
    ExpectImageTopic(mcap, "/bayer/image_raw", "sensor_msgs/msg/Image");
  }
  const json tar = Recording("ros2.tar");
  EXPECT_EQ(tar["format"], "rosbag2");
  EXPECT_EQ(tar["storage"], "sqlite3");
  ExpectImageTopic(tar, "/cam1/image_raw", "sensor_msgs/msg/Image");
}

TEST_F(ServerRecordingTest, Ros2BagFolderIsIndexedWhenWhole) {
  ASSERT_EQ(PutWhole("bag/metadata.yaml", Written("ros2_db3/metadata.yaml"))->status, 201);
  ASSERT_EQ(PutWhole("bag/ros2_db3_0.db3", Written("ros2_db3/ros2_db3_0.db3"))->status, 201);
  // One of the two files the metadata lists is still missing: the listing says which.
  const json waiting = Recording("bag");
  EXPECT_FALSE(waiting.contains("topics"));
  EXPECT_NE(waiting["problem"].get<std::string>().find("ros2_db3_1.db3"), std::string::npos)
      << waiting.dump();
  ASSERT_EQ(UploadInChunks("bag/ros2_db3_1.db3", Written("ros2_db3/ros2_db3_1.db3"))->status, 201);
  const json whole = Recording("bag");
  EXPECT_EQ(whole["format"], "rosbag2");
  EXPECT_FALSE(whole.contains("problem")) << whole.dump();
  ExpectImageTopic(whole, "/cam0/image_raw", "sensor_msgs/msg/Image");
  ExpectImageTopic(whole, "/cam1/image_raw", "sensor_msgs/msg/Image");
  EXPECT_EQ(Dataset()["recordings"].size(), 1u);
  EXPECT_EQ(Dataset()["image_count"], 0);
}

TEST_F(ServerRecordingTest, BagOfAKilledRecorderIsReadUpToTheCut) {
  ASSERT_EQ(PutWhole("killed.bag", Written("cut_short.bag"))->status, 201);
  const json recording = Recording("killed.bag");
  EXPECT_EQ(recording["cut_short"], true);
  EXPECT_NE(recording["note"].get<std::string>().find("no index"), std::string::npos);
  ASSERT_EQ(recording["topics"].size(), 1u);
  EXPECT_GT(recording["topics"][0]["message_count"].get<int>(), 0);
}

TEST_F(ServerRecordingTest, TruncatedAndDamagedRecordingsAreRefusedWithWhatAndWhere) {
  const std::string mcap = Written("images_lz4.mcap");
  const auto cut_mcap = UploadInChunks("cut.mcap", mcap.substr(0, mcap.size() - 100));
  ExpectCorrupt(cut_mcap, "cut.mcap", "closing magic");
  EXPECT_EQ(JsonOf(cut_mcap)["error"]["details"]["byte_offset"], mcap.size() - 100);

  const std::string bag = Written("images_bz2.bag");
  const auto cut_bag = UploadInChunks("cut.bag", bag.substr(0, bag.size() / 2));
  ExpectCorrupt(cut_bag, "cut.bag", "cut short");
  EXPECT_EQ(JsonOf(cut_bag)["error"]["details"]["byte_offset"], bag.size() / 2);

  std::string db3 = Written("ros2_db3/ros2_db3_0.db3");
  ExpectCorrupt(PutWhole("bag/ros2_db3_0.db3", db3.substr(0, db3.size() - 4096)),
                "bag/ros2_db3_0.db3", "ros2_db3_0.db3");
  ExpectCorrupt(PutWhole("bag/metadata.yaml", "hello: world\n"), "bag/metadata.yaml",
                "not a ROS 2 bag's metadata.yaml");
  ExpectCorrupt(PutWhole("notes.bag", "just some text"), "notes.bag", "#ROSBAG V2.0");
  const std::string tar = Written("ros2_db3.tar");
  ExpectCorrupt(UploadInChunks("cut.tar", tar.substr(0, 3000)), "cut.tar", "cut.tar: byte");
  EXPECT_TRUE(Dataset()["recordings"].empty());
  EXPECT_TRUE(Dataset()["images"].empty());
}

TEST_F(ServerRecordingTest, UnsupportedFileNamesWhatIsTaken) {
  const auto result = PutWhole("run.xyz", "not an image, a video or a recording");
  ASSERT_EQ(result->status, 415) << result->body;
  const std::string message = JsonOf(result)["error"]["message"];
  for (const std::string words : {"images", "videos", "recordings", ".bag", ".mcap", "metadata.yaml"}) {
    EXPECT_NE(message.find(words), std::string::npos) << message;
  }
}

// A stereo sequence as a robot records it: written as a ROS 1 bag by python3-rosbag
// (testing/recordings/write_stereo_bag.py: cam0 raw bgr8 Images, cam1 PNG CompressedImages
// stamped 1 ms later, lz4 chunks), uploaded in chunks beside the same frames as a PNG folder.
class RecordingJobsTest : public ServerRecordingTest {
 protected:
  static constexpr int64_t kStartNs = 1700000000000000000;
  static constexpr int64_t kPeriodNs = 100000000;  // the sequence's 10 Hz

  // Renders the sequence, writes its frames and the bag, uploads both into the dataset.
  synth::StereoSequence UploadSequenceAsFolderAndBag(int num_frames) {
    synth::StereoSequenceOptions options;
    options.num_frames = num_frames;
    options.path_length_m = 1.65;
    options.width = 640;
    options.height = 480;
    options.render.noise_sigma = 1.0;
    options.render.num_threads = 2;
    synth::StereoSequence sequence = synth::MakeStereoSequence(options);
    const fs::path folder = dir_.path() / "folder";
    api::WriteStereoSequence(sequence, "room", folder.string());
    const fs::path frames = dir_.path() / "frames";
    fs::create_directories(frames);
    std::ofstream manifest(frames / "manifest.txt");
    for (size_t i = 0; i < sequence.names.size(); ++i) {
      const int64_t stamp_ns = kStartNs + static_cast<int64_t>(i) * kPeriodNs;
      cv::Mat bgr = sequence.images[0][i];
      if (bgr.channels() == 1) cv::cvtColor(bgr, bgr, cv::COLOR_GRAY2BGR);
      bgr = bgr.clone();  // continuous rows
      std::ofstream(frames / (sequence.names[i] + ".bgr"), std::ios::binary)
          .write(reinterpret_cast<const char*>(bgr.data), static_cast<std::streamsize>(bgr.total() * 3));
      fs::copy_file(folder / "cam1" / (sequence.names[i] + ".png"),
                    frames / (sequence.names[i] + ".png"));
      manifest << stamp_ns / 1000000000 << " " << stamp_ns % 1000000000 << " " << bgr.cols << " "
               << bgr.rows << " " << sequence.names[i] << ".bgr " << sequence.names[i] << ".png\n";
    }
    manifest.close();
    const std::string command = std::string(std::getenv("OMNIRIG_SOURCE_DIR")) +
                                "/testing/recordings/write_stereo_bag.py '" + frames.string() +
                                "' '" + (dir_.path() / "run.bag").string() + "' >&2";
    EXPECT_EQ(std::system(command.c_str()), 0) << command;
    const auto stored = UploadInChunks("run.bag", ReadFile(dir_.path() / "run.bag"));
    EXPECT_EQ(stored->status, 201) << stored->body;
    for (const char* camera : {"cam0", "cam1"}) {
      for (const auto& name : sequence.names) {
        const std::string file = std::string(camera) + "/" + name + ".png";
        EXPECT_EQ(PutWhole(file, ReadFile(folder / file))->status, 201) << file;
      }
    }
    return sequence;
  }

  httplib::Result Submit(const std::string& type, const json& params) {
    return client_->Post("/api/v1/jobs",
                         json{{"type", type}, {"dataset", dataset_}, {"params", params}}.dump(),
                         "application/json");
  }

  json RunJob(const std::string& type, const json& params, double timeout_s = 240) {
    const auto created = Submit(type, params);
    EXPECT_EQ(created->status, 202) << created->body;
    const std::string id = JsonOf(created)["id"];
    const json job = WaitForJob(port_, id, timeout_s);
    EXPECT_EQ(job["state"], "succeeded") << job.dump();
    json result = JsonOf(client_->Get(("/api/v1/jobs/" + id + "/result").c_str()));
    result["job_id"] = id;
    return result;
  }

};

TEST_F(RecordingJobsTest, SlamOnABagFollowsTheSameTrajectoryAsOnItsPngFolder) {
  const synth::StereoSequence sequence = UploadSequenceAsFolderAndBag(12);
  const std::string rig = SubmitFakeRelativePose(service_->state().job_types, *client_, port_,
                                                 dataset_, api::RigToJson(sequence.rig));
  const json on_folder = RunJob("slam", {{"rig", rig}});
  const json topics = {{"cam0", "/cam0/image_raw"}, {"cam1", "/cam1/image_raw/compressed"}};
  const json on_bag = RunJob("slam", {{"rig", rig}, {"recording", "run.bag"}, {"topics", topics}});
  ASSERT_EQ(on_folder["num_frames"], 12) << on_folder.dump();
  ASSERT_EQ(on_bag["num_frames"], 12) << on_bag.dump();
  EXPECT_EQ(on_bag["num_tracked"], on_folder["num_tracked"]);
  EXPECT_EQ(on_bag["input"]["kind"], "recording");
  EXPECT_EQ(on_bag["input"]["topics"], json({"/cam0/image_raw", "/cam1/image_raw/compressed"}));
  // cam1 is stamped 1 ms after cam0: within the default tolerance (a quarter of 100 ms).
  EXPECT_NEAR(on_bag["input"]["pair_tolerance_s"].get<double>(), 0.025, 1e-9);
  EXPECT_EQ(on_bag["input"]["num_unpaired"], json({0, 0}));
  // Frames are named and timed by cam0's header stamp.
  EXPECT_EQ(on_bag["frames"][3]["name"], "t1700000000.300");
  // The bag holds the very pixels of the PNGs (raw bgr8 and lossless PNG), and SLAM is
  // deterministic on one thread: the trajectories agree to rounding.
  for (int i = 0; i < 12; ++i) {
    const json& a = on_folder["frames"][i]["world_from_rig"];
    const json& b = on_bag["frames"][i]["world_from_rig"];
    ASSERT_FALSE(a.is_null()) << i;
    ASSERT_FALSE(b.is_null()) << i;
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(a["translation_m"][k].get<double>(), b["translation_m"][k].get<double>(), 1e-9)
          << "frame " << i;
    }
    for (int k = 0; k < 4; ++k) {
      EXPECT_NEAR(a["rotation_wxyz"][k].get<double>(), b["rotation_wxyz"][k].get<double>(), 1e-9)
          << "frame " << i;
    }
  }
  // trajectory.tum carries the recording's stamps.
  const std::string tum = client_->Get(("/api/v1/jobs/" + on_bag["job_id"].get<std::string>() +
                                        "/artifacts/trajectory.tum").c_str())->body;
  EXPECT_NE(tum.find("1700000000.7"), std::string::npos) << tum;

  // Every second frame of [0.2, 0.9] s after the first stamp: 0.2, 0.4, 0.6, 0.8.
  const json stepped = RunJob("slam", {{"rig", rig},
                                       {"recording", "run.bag"},
                                       {"topics", topics},
                                       {"frame_step", 2},
                                       {"start_s", 0.2},
                                       {"end_s", 0.9}});
  ASSERT_EQ(stepped["num_frames"], 4) << stepped.dump();
  EXPECT_EQ(stepped["frames"][0]["name"], "t1700000000.200");
  EXPECT_EQ(stepped["frames"][3]["name"], "t1700000000.800");
}

}  // namespace
}  // namespace omnirig::testing
