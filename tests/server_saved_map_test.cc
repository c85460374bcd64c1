// Localising in a saved map through the real HTTP server: a live slam job drives a first run
// round the synthetic room; a second live job with "map" drives another path through the same
// places in other light and is placed in the first run's world (each frame's "in_map", the
// result's localised_in_map_fraction, the ATE in the saved map's world against the rendered
// poses); a batch slam job over the second run's stored frames does the same. The saved map is
// served as slam_map.bin. Bad "map"s are refused at submission: not a slam job, not
// succeeded, missing, made with another rig.

#include <cmath>
#include <cstdio>
#include <cstring>

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>

#include "api/camera_json.h"
#include "engine/slam/evaluation.h"
#include "engine/slam/saved_map.h"
#include "server/service.h"
#include "testing/slam/revisit.h"
#include "tests/server_test_util.h"

namespace omnirig {
namespace {

using nlohmann::json;
using namespace omnirig::testing;

std::string Png(const cv::Mat& image) {
  std::vector<uchar> bytes;
  cv::imencode(".png", image, bytes);
  return std::string(bytes.begin(), bytes.end());
}

Rigid3d PoseOf(const json& pose) { return api::PoseFromJson(pose); }

class ServerSavedMapTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    first_ = new synth::StereoSequence(slam::RenderCircleRun(slam::FirstRun()));
    second_ = new synth::StereoSequence(slam::RenderCircleRun(slam::SecondRun()));
  }
  static void TearDownTestSuite() {
    delete second_;
    delete first_;
  }

  void SetUp() override {
    server::ServiceOptions options;
    options.port = 0;
    options.data_dir = dir_.path() / "data";
    options.workers.num_workers = 1;
    options.workers.threads_per_job = 2;
    options.http_threads = 8;
    options.min_free_bytes = 0;
    service_ = std::make_unique<server::Service>(options);
    port_ = service_->Start();
    client_ = MakeClient(port_);
    const json dataset =
        JsonOf(client_->Post("/api/v1/datasets", json{{"name", "rig"}}.dump(), "application/json"));
    rig_dataset_ = dataset["id"];
    rig_ = SubmitFakeRelativePose(service_->state().job_types, *client_, port_, rig_dataset_,
                                  api::RigToJson(first_->rig));
  }

  httplib::Result Create(const json& params, const std::string& dataset = "") {
    return client_->Post("/api/v1/jobs",
                         json{{"type", "slam"}, {"dataset", dataset}, {"params", params}}.dump(),
                         "application/json");
  }

  // A live job over `sequence`'s frames (each answered with its pose), finished; its id.
  std::string DriveLive(const synth::StereoSequence& sequence, const json& extra,
                        std::vector<json>* answers) {
    json params = {{"rig", rig_}, {"live", true}};
    params.update(extra);
    const auto created = Create(params);
    EXPECT_EQ(created->status, 202) << created->body;
    const std::string id = JsonOf(created)["id"];
    for (size_t i = 0; i < sequence.names.size(); ++i) {
      const httplib::MultipartFormDataItems items = {
          {"cam0", Png(sequence.images[0][i]), "cam0.png", "image/png"},
          {"cam1", Png(sequence.images[1][i]), "cam1.png", "image/png"},
          {"stamp", std::to_string(sequence.timestamps_s[i]), "", ""}};
      const auto answer = client_->Post(("/api/v1/jobs/" + id + "/frames").c_str(), items);
      EXPECT_EQ(answer->status, 200) << answer->body;
      answers->push_back(JsonOf(answer));
    }
    EXPECT_EQ(client_->Post(("/api/v1/jobs/" + id + "/finish").c_str())->status, 202);
    EXPECT_EQ(WaitForJob(port_, id, 600)["state"], "succeeded");
    return id;
  }

  json Result(const std::string& job) {
    return JsonOf(client_->Get(("/api/v1/jobs/" + job + "/result").c_str()));
  }

  static std::vector<Rigid3d> Poses(const json& result) {
    std::vector<Rigid3d> poses;
    for (const json& frame : result["frames"]) poses.push_back(PoseOf(frame["world_from_rig"]));
    return poses;
  }

  // The second run's figures in the saved map's world, the first run's alignment to the
  // ground truth being the map's: checked against the targets and printed.
  void ExpectLocalisedInFirstRunsMap(const json& first, const json& second, const char* what) {
    ASSERT_EQ(second["num_tracked"], second_->names.size()) << what;
    const Rigid3d gt_from_map =
        slam::EvaluateTrajectory(Poses(first), first_->world_from_rig).gt_from_estimate;
    const std::vector<Rigid3d> estimate = Poses(second);
    double sum_sq = 0.0, max_m = 0.0, path_m = 0.0;
    for (size_t i = 0; i < estimate.size(); ++i) {
      const double error =
          ((gt_from_map * estimate[i]).translation - second_->world_from_rig[i].translation).norm();
      sum_sq += error * error;
      max_m = std::max(max_m, error);
      if (i > 0) {
        path_m +=
            (second_->world_from_rig[i].translation - second_->world_from_rig[i - 1].translation)
                .norm();
      }
    }
    const double ate_m = std::sqrt(sum_sq / estimate.size());
    const double fraction = second["localised_in_map_fraction"].get<double>();
    std::printf(
        "%s: in_map %.1f %% of %zu frames, ATE in the saved map's world %.2f mm = %.4f %% "
        "of %.2f m, max %.2f mm\n",
        what, 100.0 * fraction, estimate.size(), 1e3 * ate_m, 100.0 * ate_m / path_m, path_m,
        1e3 * max_m);
    EXPECT_GE(fraction, 0.95) << what;
    EXPECT_LE(ate_m, 0.001 * path_m) << what;
    EXPECT_LE(max_m, 0.5) << what;
  }

  static synth::StereoSequence* first_;
  static synth::StereoSequence* second_;
  TempDir dir_;
  std::unique_ptr<server::Service> service_;
  std::unique_ptr<httplib::Client> client_;
  int port_ = 0;
  std::string rig_dataset_;
  std::string rig_;
};

synth::StereoSequence* ServerSavedMapTest::first_ = nullptr;
synth::StereoSequence* ServerSavedMapTest::second_ = nullptr;

TEST_F(ServerSavedMapTest, SecondRunsLiveAndBatchLocaliseInTheFirstRunsMap) {
  std::vector<json> answers;
  const std::string first_id = DriveLive(*first_, json::object(), &answers);
  const json first = Result(first_id);
  EXPECT_TRUE(first["localised_in_map_fraction"].is_null());
  EXPECT_EQ(first["saved_map"]["artifact"], "slam_map.bin");
  EXPECT_EQ(first["saved_map"]["rig_job"], rig_);
  EXPECT_GT(first["saved_map"]["num_keyframes"].get<int>(), 5);
  // The saved map, served as an artifact, reads back (as a later process reads it).
  const auto file = client_->Get(("/api/v1/jobs/" + first_id + "/artifacts/slam_map.bin").c_str());
  ASSERT_EQ(file->status, 200);
  const slam::SavedMap saved = slam::DeserializeSavedMap(
      reinterpret_cast<const std::uint8_t*>(file->body.data()), file->body.size());
  EXPECT_EQ(saved.keyframes.size(), first["saved_map"]["num_keyframes"].get<size_t>());

  answers.clear();
  const std::string live_id = DriveLive(*second_, {{"map", first_id}}, &answers);
  int answered_in_map = 0;
  for (const json& answer : answers) answered_in_map += answer["in_map"].get<bool>() ? 1 : 0;
  EXPECT_GE(answered_in_map, 0.95 * second_->names.size());
  const json live = Result(live_id);
  EXPECT_EQ(live["saved_map"]["localised_in"], first_id);
  // The result's map is the saved one with what was added.
  EXPECT_GT(live["saved_map"]["num_keyframes"].get<int>(),
            first["saved_map"]["num_keyframes"].get<int>());
  const json trajectory =
      JsonOf(client_->Get(("/api/v1/jobs/" + live_id + "/artifacts/trajectory.json").c_str()));
  ASSERT_EQ(trajectory["frames"].size(), second_->names.size());
  EXPECT_NE(trajectory["world_frame"].get<std::string>().find(first_id), std::string::npos);
  int in_map = 0;
  for (const json& frame : trajectory["frames"]) in_map += frame["in_map"].get<bool>() ? 1 : 0;
  EXPECT_NEAR(live["localised_in_map_fraction"].get<double>(),
              static_cast<double>(in_map) / second_->names.size(), 1e-12);
  ExpectLocalisedInFirstRunsMap(first, live, "live second run");

  // A batch job over the second run's stored frames, in the first run's map.
  const std::string second_dataset =
      JsonOf(client_->Get(("/api/v1/jobs/" + live_id).c_str()))["dataset"];
  const auto batch = Create({{"rig", rig_}, {"map", first_id}}, second_dataset);
  ASSERT_EQ(batch->status, 202) << batch->body;
  const std::string batch_id = JsonOf(batch)["id"];
  ASSERT_EQ(WaitForJob(port_, batch_id, 600)["state"], "succeeded");
  ExpectLocalisedInFirstRunsMap(first, Result(batch_id), "batch second run");
}

TEST_F(ServerSavedMapTest, RefusesAMapThatIsNotASucceededSlamJobOfTheSameRig) {
  const std::string dataset = rig_dataset_;
  // Not a slam job: the rig job.
  auto answer = Create({{"rig", rig_}, {"live", true}, {"map", rig_}});
  EXPECT_EQ(answer->status, 422) << answer->body;
  EXPECT_EQ(JsonOf(answer)["error"]["code"], "wrong_job_type");
  // No such job.
  answer = Create({{"rig", rig_}, {"live", true}, {"map", "no-such-job"}});
  EXPECT_EQ(answer->status, 404) << answer->body;
  EXPECT_EQ(JsonOf(answer)["error"]["details"]["field"], "map");
  // A slam job that has not succeeded: a live job still running.
  const auto running = Create({{"rig", rig_}, {"live", true}});
  ASSERT_EQ(running->status, 202);
  const std::string running_id = JsonOf(running)["id"];
  answer = Create({{"rig", rig_}, {"live", true}, {"map", running_id}});
  EXPECT_EQ(answer->status, 422) << answer->body;
  EXPECT_EQ(JsonOf(answer)["error"]["code"], "dependency_not_ready");
  // A succeeded slam job made with another rig (the same calibration, another rig job).
  for (int i = 0; i < 2; ++i) {
    const httplib::MultipartFormDataItems items = {
        {"cam0", Png(first_->images[0][i]), "cam0.png", "image/png"},
        {"cam1", Png(first_->images[1][i]), "cam1.png", "image/png"},
        {"stamp", std::to_string(0.1 * i), "", ""}};
    ASSERT_EQ(client_->Post(("/api/v1/jobs/" + running_id + "/frames").c_str(), items)->status,
              200);
  }
  ASSERT_EQ(client_->Post(("/api/v1/jobs/" + running_id + "/finish").c_str())->status, 202);
  ASSERT_EQ(WaitForJob(port_, running_id, 300)["state"], "succeeded");
  const std::string other_rig = SubmitFakeRelativePose(service_->state().job_types, *client_, port_,
                                                       dataset, api::RigToJson(first_->rig));
  const std::string running_dataset =
      JsonOf(client_->Get(("/api/v1/jobs/" + running_id).c_str()))["dataset"];
  for (const bool live : {true, false}) {
    json params = {{"rig", other_rig}, {"map", running_id}};
    if (live) params["live"] = true;
    answer = Create(params, running_dataset);
    EXPECT_EQ(answer->status, 422) << answer->body;
    const json error = JsonOf(answer)["error"];
    EXPECT_EQ(error["code"], "invalid_input");
    EXPECT_NE(error["message"].get<std::string>().find("made with rig " + rig_), std::string::npos)
        << error.dump();
  }
  // The same rig: accepted.
  answer = Create({{"rig", rig_}, {"map", running_id}}, running_dataset);
  EXPECT_EQ(answer->status, 202) << answer->body;
  EXPECT_EQ(WaitForJob(port_, JsonOf(answer)["id"], 300)["state"], "succeeded");
}

}  // namespace
}  // namespace omnirig
