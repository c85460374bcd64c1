// Live slam jobs end to end (server/live_jobs.h): a real server on a loopback port, frames of a
// rendered sequence posted as a robot sends them, each answered with its pose; the frame
// events, the map and trajectory (and with a dense map the occupancy grid) served while the
// job runs, finish, idle timeout, cancel, the bad inputs refused while the job goes on,
// newest-wins skipping, two live jobs at once, a job tracking in a pipeline (2 threads) finished
// and canceled while frames stream in, and a live job that its server stopped running again as a
// batch job over the frames it stored.

#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <future>
#include <mutex>
#include <set>
#include <sstream>
#include <thread>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "api/camera_json.h"
#include "engine/slam/video_source.h"
#include "server/service.h"
#include "testing/slam/sequence_accuracy.h"
#include "tests/server_test_util.h"

namespace omnirig {
namespace {

using nlohmann::json;
using namespace omnirig::testing;
namespace fs = std::filesystem;

std::string Png(const cv::Mat& image) {
  std::vector<uchar> bytes;
  cv::imencode(".png", image, bytes);
  return std::string(bytes.begin(), bytes.end());
}

class ServerLiveTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    sequence_ = new synth::StereoSequence(synth::MakeStereoSequence(slam::ShortSequenceOptions(8)));
  }
  static void TearDownTestSuite() { delete sequence_; }

  void SetUp() override { Start(); }

  // With 2 threads per job a live job tracks in a pipeline (api/live_slam.h).
  void Start(int threads_per_job = 1) {
    server::ServiceOptions options;
    options.port = 0;
    options.data_dir = dir_.path() / "data";
    options.workers.num_workers = 1;
    options.workers.threads_per_job = threads_per_job;
    options.http_threads = 16;
    options.min_free_bytes = 0;
    service_ = std::make_unique<server::Service>(options);
    port_ = service_->Start();
    client_ = MakeClient(port_);
    if (rig_.empty()) {
      const json dataset = JsonOf(
          client_->Post("/api/v1/datasets", json{{"name", "rig"}}.dump(), "application/json"));
      rig_ = SubmitFakeRelativePose(service_->state().job_types, *client_, port_, dataset["id"],
                                    api::RigToJson(sequence_->rig));
    }
  }

  json CreateLive(const json& extra = json::object(), const std::string& dataset = "") {
    json params = {{"rig", rig_}, {"live", true}};
    params.update(extra);
    const auto created = client_->Post(
        "/api/v1/jobs", json{{"type", "slam"}, {"dataset", dataset}, {"params", params}}.dump(),
        "application/json");
    EXPECT_EQ(created->status, 202) << created->body;
    return JsonOf(created);
  }

  static httplib::Result PostFrame(httplib::Client& client, const std::string& job, double stamp_s,
                                   const cv::Mat& cam0, const cv::Mat& cam1) {
    const httplib::MultipartFormDataItems items = {{"cam0", Png(cam0), "cam0.png", "image/png"},
                                                   {"cam1", Png(cam1), "cam1.png", "image/png"},
                                                   {"stamp", std::to_string(stamp_s), "", ""}};
    return client.Post(("/api/v1/jobs/" + job + "/frames").c_str(), items);
  }
  static httplib::Result PostFrame(httplib::Client& client, const std::string& job, int i) {
    return PostFrame(client, job, 0.1 * i, sequence_->images[0][i], sequence_->images[1][i]);
  }

  json Finish(const std::string& job) {
    const auto finished = client_->Post(("/api/v1/jobs/" + job + "/finish").c_str());
    EXPECT_EQ(finished->status, 202) << finished->body;
    return WaitForJob(port_, job, 240);
  }

  // Two cameras' drivers sending frames back to back while the job is canceled, so that when
  // the cancel lands one frame is being tracked and another waits: each frame is tracked,
  // skipped, refused as out of order (409 stamp_not_increasing) or refused because the job has
  // ended (409 job_finished), never an error of the server. Returns the job.
  std::string CancelWhileFramesArrive() {
    const std::string busy = CreateLive()["id"];
    std::mutex mutex;
    std::condition_variable answered;
    std::vector<std::pair<int, std::string>> answers;  // (status, error code)
    auto drive = [&](int first) {
      auto client = MakeClient(port_);
      const int n = static_cast<int>(sequence_->names.size());
      for (int i = first;; i += 2) {
        const auto answer = PostFrame(*client, busy, 0.1 * i, sequence_->images[0][i % n],
                                      sequence_->images[1][i % n]);
        const int status = answer ? answer->status : -1;
        const json body = answer ? JsonOf(answer) : json();
        const std::string code = body.contains("error") ? body["error"].value("code", "") : "";
        {
          std::lock_guard<std::mutex> lock(mutex);
          answers.emplace_back(status, code);
        }
        answered.notify_all();
        if (status != 200 && code != "stamp_not_increasing") return;
      }
    };
    std::thread even(drive, 0), odd(drive, 1);
    {
      std::unique_lock<std::mutex> lock(mutex);
      answered.wait(lock, [&] { return answers.size() >= 4; });
    }
    EXPECT_EQ(client_->Post(("/api/v1/jobs/" + busy + "/cancel").c_str())->status, 202);
    even.join();
    odd.join();
    EXPECT_EQ(WaitForJob(port_, busy, 60)["state"], "canceled");
    int finished = 0;
    for (const auto& [status, code] : answers) {
      EXPECT_TRUE(status == 200 ||
                  (status == 409 && (code == "stamp_not_increasing" || code == "job_finished")))
          << status << " " << code;
      finished += code == "job_finished";
    }
    EXPECT_EQ(finished, 2);  // each driver's last frame
    return busy;
  }

  json Result(const std::string& job) {
    return JsonOf(client_->Get(("/api/v1/jobs/" + job + "/result").c_str()));
  }

  static synth::StereoSequence* sequence_;
  TempDir dir_;
  std::unique_ptr<server::Service> service_;
  std::unique_ptr<httplib::Client> client_;
  int port_ = 0;
  std::string rig_;
};

synth::StereoSequence* ServerLiveTest::sequence_ = nullptr;

TEST_F(ServerLiveTest, TracksEachFrameAsItComesAndFinishesAsTheBatchJob) {
  const json job = CreateLive();
  EXPECT_EQ(job["state"], "running");
  const std::string id = job["id"];
  const std::string dataset = job["dataset"];
  ASSERT_FALSE(dataset.empty());  // a dataset of its own

  // The frame events, followed while the frames are sent, and the first refresh of the files
  // the job rewrites while it runs (written off its tracking thread: an `artifacts` event).
  std::promise<void> opened;
  std::atomic<int> frame_events{0};
  std::promise<bool> trajectory_written;
  bool trajectory_told = false;
  std::thread events([&] {
    FollowEvents(
        port_, id, 120,
        [&] {
          opened.set_value();
          return false;
        },
        [&](const std::string& type, const json& data) {
          if (type == "frame") ++frame_events;
          if (type == "artifacts" && !trajectory_told &&
              data["artifacts"] == json{"trajectory.json", "map.ply"}) {
            trajectory_told = true;
            trajectory_written.set_value(true);
          }
          return type == "job" && data["state"] == "succeeded";
        });
    if (!trajectory_told) trajectory_written.set_value(false);
  });
  opened.get_future().wait();

  const int n = static_cast<int>(sequence_->names.size());
  for (int i = 0; i < n; ++i) {
    const auto answer = PostFrame(*client_, id, i);
    ASSERT_EQ(answer->status, 200) << answer->body;
    const json frame = JsonOf(answer);
    EXPECT_EQ(frame["frame_index"], i);
    EXPECT_EQ(frame["name"], slam::FrameName(0.1 * i) + ".png");
    EXPECT_EQ(frame["state"], i == 0 ? "initialised" : "tracked") << frame.dump();
    EXPECT_TRUE(frame["keyframe"].is_boolean());
    ASSERT_TRUE(frame["world_from_rig"].is_object()) << frame.dump();
    EXPECT_EQ(frame["world_from_rig"]["rotation_wxyz"].size(), 4u);
    EXPECT_GT(frame["latency_ms"].get<double>(), 0.0);
    // Tracking gives the metric motion as the robot drives (the rendered path, to 3 cm).
    const Eigen::Vector3d moved(frame["world_from_rig"]["translation_m"][0],
                                frame["world_from_rig"]["translation_m"][1],
                                frame["world_from_rig"]["translation_m"][2]);
    const double true_m =
        (sequence_->world_from_rig[i].translation - sequence_->world_from_rig[0].translation)
            .norm();
    EXPECT_NEAR(moved.norm(), true_m, 0.03) << "frame " << i;
  }
  // The map and trajectory so far, while the job runs (once the job has told of them).
  ASSERT_TRUE(trajectory_written.get_future().get());
  const auto trajectory =
      client_->Get(("/api/v1/jobs/" + id + "/artifacts/trajectory.json").c_str());
  ASSERT_EQ(trajectory->status, 200) << trajectory->body;
  EXPECT_GE(JsonOf(trajectory)["frames"].size(), 1u);
  const auto map = client_->Get(("/api/v1/jobs/" + id + "/artifacts/map.ply").c_str());
  ASSERT_EQ(map->status, 200);
  EXPECT_EQ(map->body.rfind("ply", 0), 0u);

  const json finished = Finish(id);
  ASSERT_EQ(finished["state"], "succeeded") << finished.dump();
  events.join();
  EXPECT_EQ(frame_events.load(), n);
  const json result = Result(id);
  EXPECT_EQ(result["num_frames"], n);
  EXPECT_EQ(result["num_tracked"], n);
  EXPECT_EQ(result["live"]["num_skipped"], 0);
  EXPECT_EQ(result["live"]["ended_by"], "finish");
  for (const char* name : {"trajectory.json", "trajectory.tum", "map.ply", "report.json"}) {
    EXPECT_EQ(client_->Get(("/api/v1/jobs/" + id + "/artifacts/" + name).c_str())->status, 200)
        << name;
  }
  // Nothing sent is lost: the frames are the dataset's, named by their stamps.
  const json images = JsonOf(client_->Get(("/api/v1/datasets/" + dataset).c_str()))["images"];
  ASSERT_EQ(images.size(), 2u * n) << images.dump();
  EXPECT_EQ(images[0]["name"], "cam0/t000000.000.png");
  // A frame to the ended job: 409.
  EXPECT_EQ(PostFrame(*client_, id, 9.0, sequence_->images[0][0], sequence_->images[1][0])->status,
            409);

  // The batch job over the same frames gives the same trajectory (the live run's last frame is
  // no keyframe: not bit for bit, within a millimetre).
  const auto batch = client_->Post(
      "/api/v1/jobs",
      json{{"type", "slam"}, {"dataset", dataset}, {"params", {{"rig", rig_}}}}.dump(),
      "application/json");
  ASSERT_EQ(batch->status, 202) << batch->body;
  const std::string batch_id = JsonOf(batch)["id"];
  ASSERT_EQ(WaitForJob(port_, batch_id, 240)["state"], "succeeded");
  const json batch_result = Result(batch_id);
  ASSERT_EQ(batch_result["frames"].size(), result["frames"].size());
  for (int i = 0; i < n; ++i) {
    EXPECT_EQ(batch_result["frames"][i]["name"], result["frames"][i]["name"]);
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(batch_result["frames"][i]["world_from_rig"]["translation_m"][k].get<double>(),
                  result["frames"][i]["world_from_rig"]["translation_m"][k].get<double>(), 1e-3)
          << "frame " << i;
    }
  }
}

// A ROS map_server PGM (binary P5, 8-bit): its width, height and cells; empty when it is not one.
struct Pgm {
  int width = 0, height = 0;
  std::string cells;
};
Pgm ParsePgm(const std::string& bytes) {
  std::istringstream in(bytes);
  std::string magic;
  int width = 0, height = 0, max_value = 0;
  in >> magic >> width >> height >> max_value;
  if (magic != "P5" || max_value != 255 || width <= 0 || height <= 0) return {};
  in.get();  // the one whitespace before the cells
  const std::string cells = bytes.substr(static_cast<size_t>(in.tellg()));
  if (cells.size() != static_cast<size_t>(width) * height) return {};
  return {width, height, cells};
}

TEST_F(ServerLiveTest, TheOccupancyGridIsServedWhileTheJobRunsAndMadeAgainAtTheEnd) {
  // Keyframes 0.25 m apart on this 1.05 m run, on the full-resolution grid (as slam_job_test's
  // dense map of the short sequence: at 640x480 a coarser grid leaves few points).
  const json job =
      CreateLive({{"dense_map", {{"keyframe_spacing_m", 0.25}, {"grid_step_factor", 1}}}});
  const std::string id = job["id"];
  // The job tells of each refresh of its files: the first grid with occupied cells is awaited.
  std::promise<void> opened;
  std::promise<bool> grid_written;
  bool grid_told = false;
  std::thread events([&] {
    FollowEvents(
        port_, id, 240,
        [&] {
          opened.set_value();
          return false;
        },
        [&](const std::string& type, const json& data) {
          if (type == "artifacts" && !grid_told &&
              data["artifacts"] == json{"occupancy.pgm", "occupancy.yaml"}) {
            EXPECT_GE(data["num_fused_keyframes"].get<int>(), 2) << data.dump();
            grid_told = true;
            grid_written.set_value(true);
          }
          return type == "job" && data["state"] == "succeeded";
        });
    if (!grid_told) grid_written.set_value(false);
  });
  opened.get_future().wait();
  const int n = static_cast<int>(sequence_->names.size());
  for (int i = 0; i < n; ++i) EXPECT_EQ(PostFrame(*client_, id, i)->status, 200);
  const bool written = grid_written.get_future().get();
  EXPECT_TRUE(written);
  // The grid so far, served while the job runs (not finished: it waits for /finish).
  EXPECT_EQ(JsonOf(client_->Get(("/api/v1/jobs/" + id).c_str()))["state"], "running");
  const auto pgm = client_->Get(("/api/v1/jobs/" + id + "/artifacts/occupancy.pgm").c_str());
  const auto yaml = client_->Get(("/api/v1/jobs/" + id + "/artifacts/occupancy.yaml").c_str());
  EXPECT_EQ(pgm->status, 200) << pgm->body;
  EXPECT_EQ(yaml->status, 200) << yaml->body;
  const Pgm live = ParsePgm(pgm->body);
  EXPECT_GT(live.width * live.height, 1) << pgm->body.substr(0, 20);
  EXPECT_GT(std::count(live.cells.begin(), live.cells.end(), '\0'), 0);    // occupied cells
  EXPECT_GT(std::count(live.cells.begin(), live.cells.end(), '\xfe'), 0);  // free cells
  // Its yaml names the served image (not the temporary it was written as), at the cell size.
  EXPECT_NE(yaml->body.find("image: occupancy.pgm\n"), std::string::npos) << yaml->body;
  EXPECT_NE(yaml->body.find("resolution: 0.05\n"), std::string::npos) << yaml->body;
  // Nothing of the grid is listed as a recorded artifact while it runs.
  EXPECT_EQ(JsonOf(client_->Get(("/api/v1/jobs/" + id + "/artifacts").c_str())).size(), 0u);

  const json finished = Finish(id);
  events.join();
  ASSERT_EQ(finished["state"], "succeeded") << finished.dump();
  const json result = Result(id);
  EXPECT_EQ(result["artifacts"]["occupancy_pgm"], "occupancy.pgm");
  EXPECT_GE(result["dense_map"]["keyframes"].size(), 2u) << result["dense_map"].dump();
  const auto final_pgm = client_->Get(("/api/v1/jobs/" + id + "/artifacts/occupancy.pgm").c_str());
  ASSERT_EQ(final_pgm->status, 200);
  const Pgm grid = ParsePgm(final_pgm->body);
  EXPECT_GT(std::count(grid.cells.begin(), grid.cells.end(), '\0'), 0);
  const json listed = JsonOf(client_->Get(("/api/v1/jobs/" + id + "/artifacts").c_str()));
  std::set<std::string> names;
  for (const json& artifact : listed) names.insert(artifact["name"].get<std::string>());
  EXPECT_TRUE(names.count("occupancy.pgm") && names.count("occupancy.yaml")) << listed.dump();
  for (const std::string& name : names) EXPECT_EQ(name.find(".part-live"), std::string::npos);
}

TEST_F(ServerLiveTest, CancelEndsALiveJobWhoseGridIsBeingMade) {
  // Canceled while keyframes wait for (or are in) their dense stereo: the job ends canceled, its
  // publisher's threads stopped, and the server goes on.
  const std::string id =
      CreateLive({{"dense_map", {{"keyframe_spacing_m", 0.1}, {"grid_step_factor", 1}}}})["id"];
  for (int i = 0; i < 4; ++i) EXPECT_EQ(PostFrame(*client_, id, i)->status, 200);
  EXPECT_EQ(client_->Post(("/api/v1/jobs/" + id + "/cancel").c_str())->status, 202);
  EXPECT_EQ(WaitForJob(port_, id, 120)["state"], "canceled");
  EXPECT_EQ(PostFrame(*client_, id, 4)->status, 409);
  EXPECT_EQ(client_->Get("/api/v1/health")->status, 200);
}

TEST_F(ServerLiveTest, RefusesBadFramesAndGoesOn) {
  const std::string id = CreateLive()["id"];
  ASSERT_EQ(PostFrame(*client_, id, 0)->status, 200);
  // Another size than the rig's: 422 naming both.
  const cv::Mat small(240, 320, CV_8UC3, cv::Scalar(90, 90, 90));
  const auto wrong = PostFrame(*client_, id, 0.15, small, small);
  ASSERT_EQ(wrong->status, 422) << wrong->body;
  const std::string message = JsonOf(wrong)["error"]["message"];
  EXPECT_NE(message.find("320x240"), std::string::npos) << message;
  EXPECT_NE(message.find("640x480"), std::string::npos) << message;
  // A stamp not after the last one: 409 with the last stamp.
  const auto early = PostFrame(*client_, id, 0.0, sequence_->images[0][1], sequence_->images[1][1]);
  ASSERT_EQ(early->status, 409) << early->body;
  EXPECT_EQ(JsonOf(early)["error"]["code"], "stamp_not_increasing");
  EXPECT_DOUBLE_EQ(JsonOf(early)["error"]["details"]["last_stamp_s"].get<double>(), 0.0);
  // Neither pair nor stacked: 400.
  const auto lone = client_->Post(
      ("/api/v1/jobs/" + id + "/frames").c_str(),
      httplib::MultipartFormDataItems{{"cam0", Png(sequence_->images[0][1]), "a.png", "image/png"},
                                      {"stamp", "0.2", "", ""}});
  EXPECT_EQ(lone->status, 400) << lone->body;
  // The job goes on: the next frame, stacked this time (cam0 on top), is tracked.
  cv::Mat stacked;
  cv::vconcat(sequence_->images[0][1], sequence_->images[1][1], stacked);
  const auto next =
      client_->Post(("/api/v1/jobs/" + id + "/frames").c_str(),
                    httplib::MultipartFormDataItems{{"stacked", Png(stacked), "s.png", "image/png"},
                                                    {"stamp", "0.1", "", ""}});
  ASSERT_EQ(next->status, 200) << next->body;
  EXPECT_EQ(JsonOf(next)["state"], "tracked");
  EXPECT_EQ(JsonOf(next)["frame_index"], 1);
  // Frames to a job that is not live: 409.
  EXPECT_EQ(PostFrame(*client_, rig_, 5)->status, 409);
  ASSERT_EQ(Finish(id)["state"], "succeeded");
  EXPECT_EQ(Result(id)["num_frames"], 2);
}

TEST_F(ServerLiveTest, SkipsOlderFramesWaitingAndTwoJobsBothAdvance) {
  // Two robots sending every frame at once, as fast as the server stores them: each job tracks
  // the newest and skips the older ones waiting, and counts its own.
  const std::string jobs[2] = {CreateLive()["id"], CreateLive()["id"]};
  const int n = static_cast<int>(sequence_->names.size());
  std::mutex mutex;
  std::map<std::string, std::vector<json>> answers;
  std::vector<std::thread> senders;
  for (const std::string& job : jobs) {
    senders.emplace_back([&, job] {
      // Each frame from its own connection, sent once the previous one is stored (posted in
      // stamp order), none waiting for the previous one's pose.
      std::vector<std::future<json>> pending;
      for (int i = 0; i < n; ++i) {
        pending.push_back(std::async(std::launch::async, [&, job, i] {
          auto client = MakeClient(port_);
          const auto answer = PostFrame(*client, job, i);
          return answer ? JsonOf(answer) : json{{"status", "no answer"}};
        }));
        const std::string dataset =
            JsonOf(MakeClient(port_)->Get(("/api/v1/jobs/" + job).c_str()))["dataset"];
        while (JsonOf(MakeClient(port_)->Get(
                   ("/api/v1/datasets/" + dataset).c_str()))["image_count"] < 2 * (i + 1)) {
          std::this_thread::yield();
        }
      }
      for (auto& answer : pending) {
        const json frame = answer.get();
        std::lock_guard<std::mutex> lock(mutex);
        answers[job].push_back(frame);
      }
    });
  }
  for (auto& sender : senders) sender.join();
  for (const std::string& job : jobs) {
    int tracked = 0, skipped = 0;
    for (const json& frame : answers[job]) {
      ASSERT_TRUE(frame.contains("state")) << frame.dump();
      (frame["state"] == "skipped" ? skipped : tracked)++;
      if (frame["state"] == "skipped") {
        EXPECT_TRUE(frame["frame_index"].is_null());
        EXPECT_TRUE(frame["world_from_rig"].is_null());
      }
    }
    EXPECT_EQ(tracked + skipped, n);
    EXPECT_GE(tracked, 2) << job;  // the first frame and the last are always tracked
    ASSERT_EQ(Finish(job)["state"], "succeeded");
    const json result = Result(job);
    EXPECT_EQ(result["num_frames"], tracked);
    EXPECT_EQ(result["live"]["num_skipped"], skipped);
    EXPECT_EQ(result["live"]["num_received"], n);
  }
}

TEST_F(ServerLiveTest, IdleTimeoutFinishesAndCancelEnds) {
  const std::string idle = CreateLive({{"live_idle_timeout_s", 3.0}})["id"];
  ASSERT_EQ(PostFrame(*client_, idle, 0)->status, 200);
  ASSERT_EQ(PostFrame(*client_, idle, 1)->status, 200);
  const json done = WaitForJob(port_, idle, 120);
  ASSERT_EQ(done["state"], "succeeded") << done.dump();
  EXPECT_EQ(Result(idle)["live"]["ended_by"], "idle_timeout");

  const std::string canceled = CreateLive()["id"];
  ASSERT_EQ(PostFrame(*client_, canceled, 0)->status, 200);
  EXPECT_EQ(client_->Post(("/api/v1/jobs/" + canceled + "/cancel").c_str())->status, 202);
  EXPECT_EQ(WaitForJob(port_, canceled, 60)["state"], "canceled");
  EXPECT_EQ(PostFrame(*client_, canceled, 1)->status, 409);

  const std::string busy = CancelWhileFramesArrive();

  // A live job's start forgets the live jobs whose threads are done (joined): a frame to one of
  // them is refused as finished all the same.
  for (const std::string& ended : {idle, canceled, busy}) {
    const auto answer =
        PostFrame(*client_, ended, 100.0, sequence_->images[0][0], sequence_->images[1][0]);
    ASSERT_TRUE(answer);
    EXPECT_EQ(answer->status, 409) << ended;
    EXPECT_EQ(JsonOf(answer)["error"]["code"], "job_finished") << answer->body;
  }
}

// With 2 threads a job tracks in a pipeline: the front end of the newest frame waiting (features,
// stereo) beside the back end of the frame before. Every frame sent back to back, each from its
// own connection once the previous one is stored, and the finish at once after the last: each
// frame is tracked (frame indices consecutive in stamp order) or skipped while it waited, and
// the last one, waiting or in its front end when the finish lands, is tracked before the job
// finishes. Then a cancel while frames stream in: a frame in its front end hears that the job
// has ended.
TEST_F(ServerLiveTest, APipelinedJobTracksTheFrameInItsFrontEndBeforeFinishing) {
  client_.reset();
  service_.reset();
  Start(/*threads_per_job=*/2);
  const json job = CreateLive();
  const std::string id = job["id"];
  const std::string dataset = job["dataset"];
  const int n = static_cast<int>(sequence_->names.size());
  std::vector<std::future<std::pair<int, json>>> pending;
  for (int i = 0; i < n; ++i) {
    pending.push_back(std::async(std::launch::async, [&, i] {
      auto client = MakeClient(port_);
      const auto answer = PostFrame(*client, id, i);
      return answer ? std::make_pair(answer->status, JsonOf(answer))
                    : std::make_pair(-1, json(nullptr));
    }));
    while (JsonOf(MakeClient(port_)->Get(("/api/v1/datasets/" + dataset).c_str()))["image_count"] <
           2 * (i + 1)) {
      std::this_thread::yield();
    }
  }
  const auto finish = client_->Post(("/api/v1/jobs/" + id + "/finish").c_str());
  EXPECT_EQ(finish->status, 202) << finish->body;
  int tracked = 0, skipped = 0;
  for (int i = 0; i < n; ++i) {
    const auto [status, frame] = pending[i].get();
    ASSERT_EQ(status, 200) << "frame " << i << ": " << frame.dump();
    if (frame["state"] == "skipped") {
      EXPECT_TRUE(frame["frame_index"].is_null()) << frame.dump();
      ++skipped;
      continue;
    }
    EXPECT_EQ(frame["frame_index"], tracked) << frame.dump();
    EXPECT_EQ(frame["name"], slam::FrameName(0.1 * i) + ".png");
    EXPECT_TRUE(frame["world_from_rig"].is_object()) << frame.dump();
    ++tracked;
  }
  const json done = WaitForJob(port_, id, 240);
  ASSERT_EQ(done["state"], "succeeded") << done.dump();
  const json result = Result(id);
  EXPECT_EQ(result["num_frames"], tracked);
  EXPECT_EQ(result["frames"][tracked - 1]["name"], slam::FrameName(0.1 * (n - 1)) + ".png");
  EXPECT_EQ(result["live"]["num_skipped"], skipped);
  EXPECT_EQ(result["live"]["num_received"], n);
  EXPECT_EQ(result["live"]["ended_by"], "finish");

  CancelWhileFramesArrive();
}

TEST_F(ServerLiveTest, AStoppedServersLiveJobRunsAgainAsABatchJobOverItsFrames) {
  const json job = CreateLive();
  const std::string id = job["id"];
  for (int i = 0; i < 4; ++i) ASSERT_EQ(PostFrame(*client_, id, i)->status, 200);
  // The server stops (drain): the job goes back to the queue; the next server's worker runs
  // it over the 4 frames its dataset holds.
  EXPECT_EQ(service_->Drain(0), 1);
  client_.reset();
  service_.reset();
  Start();
  const json rerun = WaitForJob(port_, id, 240);
  ASSERT_EQ(rerun["state"], "succeeded") << rerun.dump();
  const json result = Result(id);
  EXPECT_EQ(result["num_frames"], 4);
  EXPECT_EQ(result["num_tracked"], 4);
  EXPECT_EQ(result["frames"][3]["name"], "t000000.300.png");
  EXPECT_FALSE(result.contains("live"));  // a batch run
}

}  // namespace
}  // namespace omnirig
