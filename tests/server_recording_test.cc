// Robot recordings through the real service: ROS 1 bags, MCAP files and ROS 2 bags (a folder's
// files, or one .tar) written by independent writers (testing/recordings/), uploaded in
// resumable chunks or whole over a real HTTP server; the dataset's JSON lists each recording's
// topics; truncated and damaged recordings are refused with 422 corrupt_recording.

#include <gtest/gtest.h>

#include <array>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "api/camera_json.h"
#include "api/synth_json.h"
#include "engine/synth/presets.h"
#include "testing/synth/calib_board.h"
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

  // Writes each stereo frame as cam0/NAME.png and cam1/NAME.png and, through
  // write_stereo_bag.py, as the bag `bag_name` (frame i stamped kStartNs + i * kPeriodNs; cam0 a
  // raw mono8 or bgr8 Image as the image is grey or colour), and uploads both into the dataset.
  void UploadFramesAsFolderAndBag(const std::vector<std::string>& names,
                                  const std::array<std::vector<cv::Mat>, 2>& images,
                                  const std::string& bag_name = "run.bag") {
    const fs::path frames = dir_.path() / ("frames_" + bag_name);
    fs::create_directories(frames);
    std::ofstream manifest(frames / "manifest.txt");
    for (size_t i = 0; i < names.size(); ++i) {
      const int64_t stamp_ns = kStartNs + static_cast<int64_t>(i) * kPeriodNs;
      const cv::Mat cam0 = images[0][i].clone();  // continuous rows
      ASSERT_TRUE(cam0.depth() == CV_8U && (cam0.channels() == 1 || cam0.channels() == 3));
      std::ofstream(frames / (names[i] + ".raw"), std::ios::binary)
          .write(reinterpret_cast<const char*>(cam0.data),
                 static_cast<std::streamsize>(cam0.total() * cam0.elemSize()));
      std::vector<uchar> png[2];
      for (int c = 0; c < 2; ++c) ASSERT_TRUE(cv::imencode(".png", images[c][i], png[c]));
      std::ofstream(frames / (names[i] + ".png"), std::ios::binary)
          .write(reinterpret_cast<const char*>(png[1].data()), static_cast<std::streamsize>(png[1].size()));
      manifest << stamp_ns / 1000000000 << " " << stamp_ns % 1000000000 << " " << cam0.cols << " "
               << cam0.rows << " " << (cam0.channels() == 1 ? "mono8" : "bgr8") << " " << names[i]
               << ".raw " << names[i] << ".png\n";
      for (int c = 0; c < 2; ++c) {
        const std::string file = "cam" + std::to_string(c) + "/" + names[i] + ".png";
        const std::string bytes(png[c].begin(), png[c].end());
        ASSERT_EQ(PutWhole(file, bytes)->status, 201) << file;
      }
    }
    manifest.close();
    const fs::path bag = dir_.path() / bag_name;
    const std::string command = std::string(std::getenv("OMNIRIG_SOURCE_DIR")) +
                                "/testing/recordings/write_stereo_bag.py '" + frames.string() +
                                "' '" + bag.string() + "' >&2";
    ASSERT_EQ(std::system(command.c_str()), 0) << command;
    const auto stored = UploadInChunks(bag_name, ReadFile(bag));
    ASSERT_EQ(stored->status, 201) << stored->body;
  }

  synth::StereoSequence UploadSequenceAsFolderAndBag(int num_frames) {
    synth::StereoSequenceOptions options;
    options.num_frames = num_frames;
    options.path_length_m = 1.65;
    options.width = 640;
    options.height = 480;
    options.render.noise_sigma = 1.0;
    options.render.num_threads = 2;
    synth::StereoSequence sequence = synth::MakeStereoSequence(options);
    UploadFramesAsFolderAndBag(sequence.names, sequence.images);
    return sequence;
  }

  std::string Artifact(const json& result, const std::string& name) {
    return client_->Get(("/api/v1/jobs/" + result["job_id"].get<std::string>() + "/artifacts/" +
                         name).c_str())->body;
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
  const std::string tum = Artifact(on_bag, "trajectory.tum");
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

// The same sequence as ROS 2 records it: a single MCAP file (@mcap/core) and a ROS 2 bag folder
// with rosbag2's SQLite storage, both from the CDR messages @foxglove/cdr writes. Slam on each
// follows the trajectory slam follows on the PNG folder (the same pixels: cam0 raw, cam1 PNG).
TEST_F(RecordingJobsTest, SlamOnRos2RecordingsFollowsTheSameTrajectoryAsOnItsPngFolder) {
  const synth::StereoSequence sequence = UploadSequenceAsFolderAndBag(8);
  const fs::path frames = dir_.path() / "frames_run.bag";
  const fs::path cdr = dir_.path() / "cdr";
  const fs::path ros2 = dir_.path() / "bag2";
  const std::string recordings = std::string(std::getenv("OMNIRIG_SOURCE_DIR")) + "/testing/recordings/";
  const std::string write_mcap = "node " + recordings + "write_stereo_ros2.mjs '" + frames.string() +
                                 "' '" + (dir_.path() / "run.mcap").string() + "' '" + cdr.string() + "' >&2";
  ASSERT_EQ(std::system(write_mcap.c_str()), 0) << write_mcap;
  const std::string write_db3 = "/usr/bin/python3 " + recordings + "write_stereo_db3.py '" +
                                cdr.string() + "' '" + ros2.string() + "' >&2";
  ASSERT_EQ(std::system(write_db3.c_str()), 0) << write_db3;
  ASSERT_EQ(UploadInChunks("run.mcap", ReadFile(dir_.path() / "run.mcap"))->status, 201);
  ASSERT_EQ(PutWhole("bag2/metadata.yaml", ReadFile(ros2 / "metadata.yaml"))->status, 201);
  ASSERT_EQ(UploadInChunks("bag2/bag2_0.db3", ReadFile(ros2 / "bag2_0.db3"))->status, 201);

  const std::string rig = SubmitFakeRelativePose(service_->state().job_types, *client_, port_,
                                                 dataset_, api::RigToJson(sequence.rig));
  const json on_folder = RunJob("slam", {{"rig", rig}});
  const json topics = {{"cam0", "/cam0/image_raw"}, {"cam1", "/cam1/image_raw/compressed"}};
  ASSERT_EQ(on_folder["num_frames"], 8) << on_folder.dump();
  for (const std::string recording : {"run.mcap", "bag2"}) {
    const json on_recording =
        RunJob("slam", {{"rig", rig}, {"recording", recording}, {"topics", topics}});
    ASSERT_EQ(on_recording["num_frames"], 8) << recording << ": " << on_recording.dump();
    EXPECT_EQ(on_recording["num_tracked"], on_folder["num_tracked"]) << recording;
    EXPECT_EQ(on_recording["input"]["num_unpaired"], json({0, 0})) << recording;
    EXPECT_EQ(on_recording["frames"][3]["name"], "t1700000000.300") << recording;
    for (int i = 0; i < 8; ++i) {
      const json& a = on_folder["frames"][i]["world_from_rig"];
      const json& b = on_recording["frames"][i]["world_from_rig"];
      ASSERT_FALSE(a.is_null()) << i;
      ASSERT_FALSE(b.is_null()) << recording << " frame " << i;
      for (int k = 0; k < 3; ++k) {
        EXPECT_NEAR(a["translation_m"][k].get<double>(), b["translation_m"][k].get<double>(), 1e-9)
            << recording << " frame " << i;
      }
    }
  }
}

// A board waved before the rig, recorded: a calibration from cam0's topic and a rig from both
// topics agree with the same jobs on the PNG folder (the bag holds the same pixels: cam0 raw
// mono8, cam1 PNG), and their Kalibr exports name the topics.
TEST_F(RecordingJobsTest, CalibrationAndRigFromTopicsMatchTheFolder) {
  const synth::StereoBoardSet set = synth::MakeStereoBoardSet(synth::QuickStereoBoardOptions(8, 5));
  UploadFramesAsFolderAndBag(set.names, set.images);
  const json board = {{"cols", set.board.cols},
                      {"rows", set.board.rows},
                      {"square_size_mm", set.board.square_size_m * 1e3}};
  const json on_folder = RunJob("calibration", {{"board", board}, {"camera", "cam0"}});
  const json on_topic =
      RunJob("calibration", {{"board", board}, {"recording", "run.bag"}, {"topic", "/cam0/image_raw"}});
  ASSERT_EQ(on_topic["num_views_used"], on_folder["num_views_used"]) << on_topic.dump();
  EXPECT_EQ(on_topic["num_views_used"], 8);
  EXPECT_NEAR(on_topic["rms_px"].get<double>(), on_folder["rms_px"].get<double>(), 1e-9);
  EXPECT_EQ(on_topic["camera"]["intrinsics"], on_folder["camera"]["intrinsics"]);
  EXPECT_EQ(on_topic["images"][2]["name"], "t1700000000.200.msg");
  EXPECT_EQ(on_topic["input"]["num_frames"], 8);
  EXPECT_NE(Artifact(on_topic, "camera_kalibr.yaml").find("  rostopic: /cam0/image_raw\n"),
            std::string::npos);
  EXPECT_EQ(Artifact(on_folder, "camera_kalibr.yaml").find("rostopic"), std::string::npos);

  const json topics = {{"cam0", "/cam0/image_raw"}, {"cam1", "/cam1/image_raw/compressed"}};
  const json rig_on_folder = RunJob("relative_pose", {{"board", board}});
  const json rig_on_topics =
      RunJob("relative_pose", {{"board", board}, {"recording", "run.bag"}, {"topics", topics}});
  EXPECT_NEAR(rig_on_topics["baseline_m"].get<double>(), rig_on_folder["baseline_m"].get<double>(),
              1e-9);
  EXPECT_NEAR(rig_on_topics["baseline_m"].get<double>(), set.rig.cam0_from_cam1.translation.norm(),
              1e-3);
  EXPECT_EQ(rig_on_topics["input"]["num_unpaired"], json({0, 0}));
  const std::string camchain = Artifact(rig_on_topics, "camchain_kalibr.yaml");
  EXPECT_NE(camchain.find("  rostopic: /cam0/image_raw\n"), std::string::npos) << camchain;
  EXPECT_NE(camchain.find("  rostopic: /cam1/image_raw/compressed\n"), std::string::npos)
      << camchain;

  // Sparse stereo on two of the recording's pairs with that rig.
  const json stereo = RunJob("stereo_reconstruct", {{"rig", rig_on_topics["job_id"]},
                                                    {"method", "sparse"},
                                                    {"recording", "run.bag"},
                                                    {"topics", topics},
                                                    {"end_s", 0.15}});
  ASSERT_EQ(stereo["pairs"].size(), 2u) << stereo.dump();
  EXPECT_EQ(stereo["pairs"][1]["name"], "t1700000000.100.msg");
  EXPECT_GT(stereo["num_points"].get<int>(), 0);
}

// Every bad recording input is refused at submission, 422 invalid_input, with what to write.
TEST_F(RecordingJobsTest, BadRecordingInputsAreRefusedAtSubmission) {
  ASSERT_EQ(UploadInChunks("run.bag", Written("images_none.bag"))->status, 201);
  const json board = {{"cols", 7}, {"rows", 5}, {"square_size_mm", 30}};
  const json pair = {{"cam0", "/cam0/image_raw"}, {"cam1", "/cam1/image_raw"}};
  const auto expect = [&](const std::string& type, json params, const std::string& words) {
    const auto result = Submit(type, params);
    ASSERT_TRUE(result);
    EXPECT_EQ(result->status, 422) << type << " " << params.dump() << ": " << result->body;
    const json body = JsonOf(result);
    EXPECT_EQ(body["error"]["code"], "invalid_input") << result->body;
    EXPECT_NE(body["error"]["message"].get<std::string>().find(words), std::string::npos)
        << type << " " << params.dump() << ": " << result->body;
  };
  const std::string image_topics =
      "its image topics are /bayer/image_raw, /cam0/image_raw, /cam0/image_raw/compressed, "
      "/cam1/image_raw";
  // An unknown recording, a topic it does not hold, a topic of another type.
  expect("calibration", {{"board", board}, {"recording", "nope.bag"}, {"topic", "/cam0/image_raw"}},
         "the dataset holds no recording 'nope.bag' (its recordings: run.bag)");
  expect("calibration", {{"board", board}, {"recording", "run.bag"}, {"topic", "/cam2/image_raw"}},
         "recording run.bag has no topic /cam2/image_raw: " + image_topics);
  expect("calibration", {{"board", board}, {"recording", "run.bag"}, {"topic", "/note"}},
         "topic /note of recording run.bag holds std_msgs/String messages, not images "
         "(sensor_msgs/Image or CompressedImage): " + image_topics);
  expect("relative_pose",
         {{"board", board}, {"recording", "run.bag"}, {"topics", {{"cam0", "/cam0/image_raw"}, {"cam1", "/note"}}}},
         "topic /note of recording run.bag holds std_msgs/String");
  // "topics" on a calibration, "topic" on the stereo jobs, topics without a recording.
  expect("calibration", {{"board", board}, {"recording", "run.bag"}, {"topics", pair}},
         "a calibration reads one camera: name its topic with \"topic\"");
  expect("relative_pose", {{"board", board}, {"recording", "run.bag"}, {"topic", "/cam0/image_raw"}},
         "this job reads two cameras: name their topics with \"topics\"");
  expect("calibration", {{"board", board}, {"topic", "/cam0/image_raw"}},
         "'topic' names topics of a recording: add \"recording\"");
  expect("relative_pose", {{"board", board}, {"recording", "run.bag"}, {"topics", {{"cam0", "/cam0/image_raw"}}}},
         "field 'params.topics' must be {\"cam0\": TOPIC, \"cam1\": TOPIC}");
  // A recording and a folder of images at once.
  expect("calibration",
         {{"board", board}, {"recording", "run.bag"}, {"topic", "/cam0/image_raw"}, {"camera", "cam0"}},
         "\"camera\" picks a folder of the dataset's images and \"recording\" a topic of a "
         "recording: give one of them");
  // A job on the recording that does not name it is told how to.
  const auto unnamed = Submit("calibration", {{"board", board}});
  EXPECT_EQ(unnamed->status, 422) << unnamed->body;
  EXPECT_NE(unnamed->body.find("has no images but the recording run.bag: name it with"),
            std::string::npos) << unnamed->body;
  // The slam and stereo jobs (their rig from a stand-in relative_pose job).
  const std::string rig = SubmitFakeRelativePose(service_->state().job_types, *client_, port_,
                                                 dataset_, json{{"baseline_m", 0.1}});
  expect("slam", {{"rig", rig}, {"recording", "run.bag"}, {"topic", "/cam0/image_raw"}},
         "this job reads two cameras");
  expect("slam", {{"rig", rig}, {"recording", "other.mcap"}, {"topics", pair}},
         "the dataset holds no recording 'other.mcap'");
  expect("slam", {{"rig", rig}, {"recording", "run.bag"}, {"topics", {{"cam0", "/cam0/image_raw"}, {"cam1", "/cam3"}}}},
         "recording run.bag has no topic /cam3: " + image_topics);
  expect("stereo_reconstruct", {{"rig", rig}, {"recording", "run.bag"}, {"topic", "/cam0/image_raw"}},
         "this job reads two cameras");
  expect("stereo_reconstruct", {{"rig", rig}, {"recording", "run.bag"}, {"topics", {{"cam0", "/note"}, {"cam1", "/cam1/image_raw"}}}},
         "topic /note of recording run.bag holds std_msgs/String");
  // The good params pass (the tiny 32x24 frames fit no rig: canceled once queued).
  const auto accepted = Submit("slam", {{"rig", rig}, {"recording", "run.bag"}, {"topics", pair}});
  ASSERT_EQ(accepted->status, 202) << accepted->body;
  client_->Post(("/api/v1/jobs/" + JsonOf(accepted)["id"].get<std::string>() + "/cancel").c_str(),
                "", "application/json");
}

}  // namespace
}  // namespace omnirig::testing
