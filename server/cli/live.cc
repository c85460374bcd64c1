// `omnirig live`: plays a recording against a server as the robot that captured it would send
// it, and reports what the robot would have met. Starts a live slam job, captures every stereo
// frame at its time (the recording's stamps, or --rate) and sends it as a camera driver does.
// By default (--in-flight 1) one frame at a time, with a queue of one: while the server is still
// tracking the last frame sent, the frames captured meanwhile wait, and only the newest of them
// goes next (the others are counted skipped by the client); each pose is then as fresh as the
// server can make it. With --in-flight N each frame is posted as it is captured while fewer than
// N requests are outstanding (each on a connection of its own): the server tracks the newest
// frame it holds, runs the next frame's front end beside the back end of the one before, and
// answers the frames it could not reach "skipped" (more frames tracked, each pose later:
// docs/slam.md). There, a frame that reaches the server after a newer one (409
// stamp_not_increasing: requests on several connections can overtake one another under load)
// is counted skipped.
// Then it finishes the job and prints the latency percentiles (receipt to pose, as the server
// measures it; the round trip the client saw; capture to pose, the robot's wait), the frames
// tracked and skipped, the loops, and the trajectory against a ground truth (a .tum beside the
// images, one pose per frame, as the batch slam job reads it) when there is one.
//
// A recording: a folder of cam0/NAME and cam1/NAME images (NAME the capture time, as
// "1403636579.763.png" or "t000012.345.png"; other names are played at --rate, default 10 Hz),
// or videos (cam0.EXT cam1.EXT, or stacked.EXT, cam0 on top), whose frames are sent as PNGs.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <future>
#include <iomanip>
#include <iostream>
#include <map>
#include <mutex>
#include <optional>
#include <sstream>
#include <thread>

#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "api/camera_json.h"
#include "api/relpose_job.h"
#include "engine/util/image_pairs.h"
#include "api/slam_job.h"
#include "engine/slam/evaluation.h"
#include "engine/slam/map_io.h"
#include "engine/slam/video_source.h"
#include "engine/util/check.h"
#include "server/cli/args.h"
#include "server/cli/commands.h"

// After Eigen (through api/): httplib.h pulls in system headers whose macros break Eigen's.
#include <httplib.h>

namespace omnirig::cli {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using Clock = std::chrono::steady_clock;

// One frame of the recording: its stamp and a way to get its two files' bytes.
struct RecordedFrame {
  double stamp_s = 0;
  std::function<std::pair<std::string, std::string>()> read;  // (cam0, cam1) file bytes
  std::string format;                                         // ".png", ".jpg", ...
};

std::string ReadBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  OMNIRIG_CHECK(in, "cannot read " << path.string());
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

std::string Png(const cv::Mat& image) {
  std::vector<uchar> bytes;
  cv::imencode(".png", image, bytes);
  return std::string(bytes.begin(), bytes.end());
}

// The recording's frames, in order; `ground_truth` gets the .tum beside them, if any.
std::vector<RecordedFrame> ReadRecording(const std::vector<std::string>& inputs, double rate_hz,
                                         std::optional<fs::path>* ground_truth) {
  std::vector<RecordedFrame> frames;
  if (inputs.size() == 1 && fs::is_directory(inputs[0])) {
    const fs::path dir = inputs[0];
    std::vector<std::string> names;
    for (const auto& entry : fs::recursive_directory_iterator(dir)) {
      if (!entry.is_regular_file()) continue;
      const std::string name = fs::relative(entry.path(), dir).generic_string();
      if (entry.path().extension() == ".tum" && name.find('/') == std::string::npos) {
        *ground_truth = entry.path();
      }
      names.push_back(name);
    }
    std::sort(names.begin(), names.end());
    const auto videos = api::FindStereoVideos(dir, names);
    if (!videos) {
      const std::vector<ImagePairNames> pairs = MatchImagePairs(names);
      bool stamped = rate_hz <= 0;
      for (const auto& pair : pairs) stamped = stamped && NameAsTimestamp(pair.name);
      for (size_t i = 0; i < pairs.size(); ++i) {
        RecordedFrame frame;
        frame.stamp_s = stamped ? *NameAsTimestamp(pairs[i].name)
                                : static_cast<double>(i) / (rate_hz > 0 ? rate_hz : 10.0);
        frame.format = fs::path(pairs[i].cam0).extension().string();
        const fs::path cam0 = dir / pairs[i].cam0, cam1 = dir / pairs[i].cam1;
        frame.read = [cam0, cam1] { return std::make_pair(ReadBytes(cam0), ReadBytes(cam1)); };
        frames.push_back(std::move(frame));
      }
      return frames;
    }
    return ReadRecording({videos->cam0.string(), videos->cam1.string()}, rate_hz, ground_truth);
  }
  OMNIRIG_CHECK(!inputs.empty() && inputs.size() <= 2,
                "give a folder of cam0/ cam1/ images, or cam0 and cam1 videos, or one stacked "
                "video");
  const slam::StereoVideoFiles files{inputs[0], inputs.size() == 2 ? inputs[1] : ""};
  std::vector<slam::StereoVideoFrame> paired = slam::PairStereoVideoFrames(files, {});
  auto reader = std::make_shared<slam::StereoVideoReader>(files, paired);
  auto mutex = std::make_shared<std::mutex>();
  for (size_t i = 0; i < paired.size(); ++i) {
    RecordedFrame frame;
    frame.stamp_s = paired[i].timestamp_s;
    frame.format = ".png";
    frame.read = [reader, mutex, i] {
      std::lock_guard<std::mutex> lock(*mutex);
      const slam::StereoImages images = reader->Load(static_cast<int>(i));
      return std::make_pair(Png(images.cam0), Png(images.cam1));
    };
    frames.push_back(std::move(frame));
  }
  return frames;
}

json Expect(const httplib::Result& result, std::initializer_list<int> ok, const std::string& what) {
  if (!result) throw std::runtime_error(what + ": " + httplib::to_string(result.error()));
  const json body = json::parse(result->body, nullptr, false);
  for (int status : ok) {
    if (result->status == status) return body;
  }
  const std::string message = body.is_object() && body.contains("error")
                                  ? body["error"].value("message", result->body)
                                  : result->body;
  throw std::runtime_error(what + ": HTTP " + std::to_string(result->status) + ": " + message);
}

double Percentile(std::vector<double> values, double p) {
  if (values.empty()) return 0.0;
  std::sort(values.begin(), values.end());
  const size_t rank = static_cast<size_t>(std::ceil(p / 100.0 * values.size()));
  return values[std::clamp<size_t>(rank, 1, values.size()) - 1];
}

json Percentiles(const std::vector<double>& values) {
  return {{"p50", Percentile(values, 50)},
          {"p95", Percentile(values, 95)},
          {"p99", Percentile(values, 99)},
          {"max", Percentile(values, 100)}};
}

std::unique_ptr<httplib::Client> Connect(const std::string& server, const std::string& token) {
  auto client = std::make_unique<httplib::Client>(server);
  client->set_read_timeout(600, 0);
  client->set_write_timeout(60, 0);
  if (!token.empty()) client->set_bearer_token_auth(token.c_str());
  return client;
}

// The estimate of the frames that have a pose in the finished job's trajectory.json, against
// the ground truth (one pose per recorded frame, in order; frames matched by stamp).
json Evaluate(const json& trajectory, const fs::path& ground_truth,
              const std::vector<RecordedFrame>& frames) {
  const std::vector<slam::StampedPose> truth = slam::ReadTum(ground_truth);
  OMNIRIG_CHECK(truth.size() == frames.size(), ground_truth.filename().string()
                                                   << " has " << truth.size() << " poses for "
                                                   << frames.size() << " frames");
  std::map<std::string, size_t> index_of_name;
  for (size_t i = 0; i < frames.size(); ++i) index_of_name[slam::FrameName(frames[i].stamp_s)] = i;
  std::vector<Rigid3d> estimate, matched;
  for (const json& frame : trajectory["frames"]) {
    if (frame["world_from_rig"].is_null()) continue;
    const std::string stem = fs::path(frame["name"].get<std::string>()).stem().string();
    const auto it = index_of_name.find(stem);
    if (it == index_of_name.end()) continue;
    estimate.push_back(api::PoseFromJson(frame["world_from_rig"]));
    matched.push_back(truth[it->second].world_from_rig);
  }
  if (estimate.size() < 2) return nullptr;
  const slam::TrajectoryErrors errors = slam::EvaluateTrajectory(estimate, matched);
  return {{"num_poses", errors.num_poses},
          {"ate_rmse_m", errors.ate_rmse_m},
          {"ate_percent_of_path", 100.0 * errors.ate_rmse_m / std::max(errors.path_length_m, 1e-9)},
          {"path_length_m", errors.path_length_m},
          {"final_drift_percent", errors.final_drift_percent}};
}

// "20 Hz", "12.5 Hz": the rate as the user gave it.
std::string FormatHz(double rate_hz) {
  std::ostringstream text;
  text << rate_hz << " Hz";
  return text.str();
}

struct FrameOutcome {
  json answer;
  double round_trip_ms = 0;
  double late_ms = 0;  // how late the client sent it
};

void DeclareOptions(ArgParser* parser) {
  parser->SetPositional("DIR|VIDEOS",
                        "a recording: a folder of cam0/ and cam1/ images named by "
                        "their capture time, or cam0 and cam1 videos, or a stacked "
                        "video (cam0 on top)");
  parser->AddOption("rig", "", "the rig: a succeeded relative_pose job on the server (required)");
  parser->AddOption("map", "",
                    "localise in this succeeded slam job's saved map (its world, its landmarks)");
  parser->AddOption("rate", "0",
                    "frames per second to send (0: the recording's own capture times)");
  parser->AddOption("server", "http://127.0.0.1:8080", "server URL");
  parser->AddOption("token", "", "bearer token (default: $OMNIRIG_TOKEN)");
  parser->AddOption("params", "{}", "more slam params as JSON (e.g. {\"options\": {...}})");
  parser->AddOption("dataset", "", "store the frames in this dataset (default: a new one)");
  parser->AddOption("ground-truth", "", "a .tum of the recording (default: the folder's .tum)");
  parser->AddOption("json", "", "also write the figures to this file, as JSON");
  parser->AddOption("in-flight", "1",
                    "frames outstanding at once: 1 sends the newest frame once the last one is "
                    "answered (the freshest poses); more posts each frame as it is captured and "
                    "lets the server skip (more frames tracked, each pose later)");
}

}  // namespace

int RunLive(const Args& args) {
  ArgParser parser("live", "play a recording against a server as a robot would, in real time");
  DeclareOptions(&parser);
  if (!parser.Parse(args)) return parser.exit_code();
  const std::string rig = parser.Get("rig");
  if (rig.empty() || parser.positional().empty()) {
    std::cerr << "omnirig live: --rig and a recording are required\n" << parser.Help();
    return 2;
  }
  const double rate_hz = parser.GetDouble("rate");
  const int in_flight = parser.GetInt("in-flight");
  OMNIRIG_CHECK(in_flight >= 1 && in_flight <= 16, "--in-flight must be from 1 to 16");
  OMNIRIG_CHECK(rate_hz >= 0 && std::isfinite(rate_hz), "--rate must be a positive number");
  std::optional<fs::path> ground_truth;
  std::vector<RecordedFrame> frames = ReadRecording(parser.positional(), rate_hz, &ground_truth);
  OMNIRIG_CHECK(!frames.empty(), "the recording holds no frame");
  if (parser.Has("ground-truth")) ground_truth = fs::path(parser.Get("ground-truth"));
  std::string token = parser.Get("token");
  if (token.empty() && std::getenv("OMNIRIG_TOKEN")) token = std::getenv("OMNIRIG_TOKEN");
  const std::string server = parser.Get("server");
  auto client = Connect(server, token);

  json params = json::parse(parser.Get("params"), nullptr, false);
  OMNIRIG_CHECK(params.is_object(), "--params must be a JSON object");
  params["rig"] = rig;
  params["live"] = true;
  if (parser.Has("map")) params["map"] = parser.Get("map");
  const json job = Expect(
      client->Post(
          "/api/v1/jobs",
          json{{"type", "slam"}, {"dataset", parser.Get("dataset")}, {"params", params}}.dump(),
          "application/json"),
      {202}, "live job");
  const std::string id = job["id"];
  std::cerr << "live job " << id << " (dataset " << job["dataset"].get<std::string>()
            << "): " << frames.size() << " frames at "
            << (rate_hz > 0 ? FormatHz(rate_hz) : std::string("capture rate")) << "\n";

  // Capture (this thread) and send (--in-flight sender threads) meet in a slot of one frame, the
  // newest; a sender takes it as soon as it is free.
  struct Captured {
    size_t index = 0;
    Clock::time_point due;
  };
  std::mutex mutex;
  std::condition_variable changed;
  std::optional<Captured> slot;
  bool captured_all = false;
  std::vector<FrameOutcome> outcomes(frames.size());
  for (FrameOutcome& outcome : outcomes) {
    outcome.answer = {{"state", "skipped"}, {"skipped_by", "client"}};
  }
  const Clock::time_point start = Clock::now();
  const auto send = [&] {
    auto connection = Connect(server, token);
    while (true) {
      Captured frame;
      {
        std::unique_lock<std::mutex> lock(mutex);
        changed.wait(lock, [&] { return slot.has_value() || captured_all; });
        if (!slot) return;
        frame = *slot;
        slot.reset();
      }
      FrameOutcome& outcome = outcomes[frame.index];
      const auto bytes = frames[frame.index].read();
      const Clock::time_point sent = Clock::now();
      outcome.late_ms = std::chrono::duration<double, std::milli>(sent - frame.due).count();
      char stamp[32];
      std::snprintf(stamp, sizeof(stamp), "%.6f", frames[frame.index].stamp_s);
      const std::string& format = frames[frame.index].format;
      const httplib::MultipartFormDataItems items = {{"cam0", bytes.first, "cam0" + format, ""},
                                                     {"cam1", bytes.second, "cam1" + format, ""},
                                                     {"stamp", stamp, "", ""}};
      const auto result = connection->Post(("/api/v1/jobs/" + id + "/frames").c_str(), items);
      outcome.round_trip_ms =
          std::chrono::duration<double, std::milli>(Clock::now() - sent).count();
      outcome.answer = result ? json::parse(result->body, nullptr, false)
                              : json{{"error", {{"message", httplib::to_string(result.error())}}}};
      // Overtaken on another connection (only possible with several in flight; one at a time,
      // such a 409 means the recording's own stamps go back, and it counts as refused).
      if (in_flight > 1 && result && result->status == 409 && outcome.answer.is_object() &&
          outcome.answer.contains("error") &&
          outcome.answer["error"].value("code", "") == "stamp_not_increasing") {
        outcome.answer = {{"state", "skipped"}, {"skipped_by", "server, after a newer frame"}};
      } else if (result && result->status != 200) {
        outcome.answer["status"] = result->status;
      }
    }
  };
  std::vector<std::thread> senders;
  for (int i = 0; i < in_flight; ++i) senders.emplace_back(send);
  for (size_t i = 0; i < frames.size(); ++i) {
    const double at_s =
        rate_hz > 0 ? static_cast<double>(i) / rate_hz : frames[i].stamp_s - frames[0].stamp_s;
    const Clock::time_point due =
        start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(at_s));
    std::this_thread::sleep_until(due);  // the camera's next exposure
    std::lock_guard<std::mutex> lock(mutex);
    slot = Captured{i, due};  // a frame still waiting here is superseded: skipped by the client
    changed.notify_one();
  }
  {
    std::lock_guard<std::mutex> lock(mutex);
    captured_all = true;
    changed.notify_all();
  }
  for (std::thread& sender : senders) sender.join();
  std::vector<double> latency_ms, round_trip_ms, late_ms, capture_to_pose_ms;
  int tracked = 0, skipped = 0, refused = 0, lost = 0;
  for (const FrameOutcome& outcome : outcomes) {
    late_ms.push_back(outcome.late_ms);
    const std::string state = outcome.answer.value("state", "");
    if (state.empty()) {
      if (refused++ == 0) std::cerr << "refused: " << outcome.answer.dump() << "\n";
      continue;
    }
    if (state == "skipped") {
      ++skipped;
      continue;
    }
    ++tracked;
    if (state == "lost") ++lost;
    latency_ms.push_back(outcome.answer["latency_ms"].get<double>());
    round_trip_ms.push_back(outcome.round_trip_ms);
    capture_to_pose_ms.push_back(outcome.late_ms + outcome.round_trip_ms);
  }
  const double played_s = std::chrono::duration<double>(Clock::now() - start).count();
  Expect(client->Post(("/api/v1/jobs/" + id + "/finish").c_str()), {202}, "finish");
  json finished;
  while (true) {
    finished = Expect(client->Get(("/api/v1/jobs/" + id).c_str()), {200}, "job " + id);
    const std::string state = finished["state"];
    if (state == "succeeded" || state == "failed" || state == "canceled") break;
    std::this_thread::sleep_for(std::chrono::milliseconds(200));  // a client's poll
  }
  json summary = {
      {"job", id},
      {"state", finished["state"]},
      {"frames_sent", frames.size()},
      {"frames_tracked", tracked},
      {"frames_skipped", skipped},
      {"frames_lost", lost},
      {"frames_refused", refused},
      {"in_flight", in_flight},
      {"rate_hz", rate_hz > 0 ? rate_hz
                              : (frames.size() - 1) /
                                    std::max(frames.back().stamp_s - frames[0].stamp_s, 1e-9)},
      {"played_s", played_s},
      {"latency_ms", Percentiles(latency_ms)},
      {"round_trip_ms", Percentiles(round_trip_ms)},
      {"capture_to_pose_ms", Percentiles(capture_to_pose_ms)},
      {"send_late_ms", Percentiles(late_ms)}};
  if (finished["state"] == "succeeded") {
    const json result =
        Expect(client->Get(("/api/v1/jobs/" + id + "/result").c_str()), {200}, "result");
    summary["loops"] = result["loops"].size();
    summary["num_keyframes"] = result["num_keyframes"];
    summary["finish_s"] = result["timings_s"]["global_ba"];
    if (result.contains("localised_in_map_fraction")) {
      summary["localised_in_map_fraction"] = result["localised_in_map_fraction"];
    }
    if (ground_truth) {
      const json trajectory =
          Expect(client->Get(("/api/v1/jobs/" + id + "/artifacts/trajectory.json").c_str()), {200},
                 "trajectory.json");
      summary["evaluation"] = Evaluate(trajectory, *ground_truth, frames);
    }
  } else {
    summary["error"] = finished["error"];
  }
  std::cout << std::fixed << std::setprecision(1) << "job " << id << " "
            << summary["state"].get<std::string>() << ": " << tracked << " of " << frames.size()
            << " frames tracked, " << skipped << " skipped (" << lost << " lost, " << refused
            << " refused)\n"
            << "latency ms (receipt to pose) p50 " << summary["latency_ms"]["p50"].get<double>()
            << " p95 " << summary["latency_ms"]["p95"].get<double>() << " p99 "
            << summary["latency_ms"]["p99"].get<double>() << "; round trip p95 "
            << summary["round_trip_ms"]["p95"].get<double>() << "\n"
            << "capture to pose ms (the robot's wait: sent late plus round trip) p50 "
            << summary["capture_to_pose_ms"]["p50"].get<double>() << " p95 "
            << summary["capture_to_pose_ms"]["p95"].get<double>() << "\n";
  if (summary.contains("loops")) std::cout << "loops " << summary["loops"].get<int>() << "\n";
  if (summary.contains("localised_in_map_fraction") &&
      summary["localised_in_map_fraction"].is_number()) {
    std::cout << "in map " << 100 * summary["localised_in_map_fraction"].get<double>()
              << " % of the frames tracked (the saved map of job " << parser.Get("map") << ")\n";
  }
  if (summary.contains("evaluation") && summary["evaluation"].is_object()) {
    std::cout << std::setprecision(4) << "ATE " << summary["evaluation"]["ate_rmse_m"].get<double>()
              << " m (" << summary["evaluation"]["ate_percent_of_path"].get<double>()
              << " % of the path)\n";
  }
  if (parser.Has("json")) {
    std::ofstream out(parser.Get("json"));
    out << summary.dump(2) << "\n";
  }
  return finished["state"] == "succeeded" ? 0 : 1;
}

}  // namespace omnirig::cli
