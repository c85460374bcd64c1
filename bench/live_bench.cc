// bench_live: a robot's recording played in real time through `omnirig live` against a server
// in this process. The recording is a loop around the synthetic city block (engine/synth/
// city_block.h; by default 600 stereo frames at 1024x768, 2 laps of a 50 m loop, each lap under
// its own light, image noise 1 grey level), rendered once into a cache folder and read from
// there later; the rig is the render's calibration (a relative_pose job whose result is that
// rig). Each rate plays the whole recording as a new live job and prints: frames tracked and
// skipped (newest wins when tracking falls behind), latency from receipt to pose as the server
// measures it (p50/p95/p99), the client's round trip and capture to pose (c2p: how late the
// client sent the frame plus the round trip), the loops closed, the ATE after the live job's
// finish (SE(3)-aligned against the render's poses, and as % of the path). --in-flight N is
// `omnirig live`'s: N frames outstanding at once; --dense-map VOXEL_M gives the live job a dense
// map (its occupancy grid made while it runs, beside the tracking).
//
// Then it profiles the tracker (slam::Session, no HTTP) over the first --profile-frames frames
// (0: none), every frame and every 10th: the mean wall and CPU milliseconds per frame of decoding
// and of each tracking stage; and every frame again in the live job's pipeline (each frame's decoding
// and front end on a thread of its own beside the back end of the frame before): the wall
// milliseconds per frame against the serial pass's. The load average is printed with the
// figures: on a shared machine the wall-clock figures grow with it.
//
// usage: bench_live [--rates 10,20,30] [--frames 600] [--laps 2] [--loop-length 50]
//                   [--width 1024] [--height 768] [--threads 2] [--supersampling 4] [--dir DIR]
//                   [--profile-frames 120] [--in-flight 1] [--dense-map VOXEL_M]

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <future>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include <opencv2/imgcodecs.hpp>

#include <nlohmann/json.hpp>

#include "api/camera_json.h"
#include "api/job_types.h"
#include "api/live_publisher.h"
#include "engine/slam/map_io.h"
#include "engine/slam/session.h"
#include "engine/synth/presets.h"
#include "engine/util/allocator.h"
#include "engine/util/timer.h"
#include "server/cli/commands.h"
#include "server/service.h"

namespace omnirig {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

struct BenchArgs {
  std::vector<double> rates = {10, 20, 30};
  int frames = 600, laps = 2, width = 1024, height = 768, threads = 2, supersampling = 4;
  double loop_length_m = 50.0;
  int profile_frames = 120;
  std::string dir;
  std::string in_flight = "1";  // omnirig live's --in-flight
  double dense_map_voxel_m = 0;   // > 0: the live job makes its dense map and occupancy grid
};

BenchArgs Parse(int argc, char** argv) {
  BenchArgs args;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string { return i + 1 < argc ? argv[++i] : ""; };
    if (a == "--rates") {
      args.rates.clear();
      std::stringstream list(next());
      for (std::string item; std::getline(list, item, ',');)
        args.rates.push_back(std::atof(item.c_str()));
    } else if (a == "--frames")
      args.frames = std::atoi(next().c_str());
    else if (a == "--laps")
      args.laps = std::atoi(next().c_str());
    else if (a == "--loop-length")
      args.loop_length_m = std::atof(next().c_str());
    else if (a == "--width")
      args.width = std::atoi(next().c_str());
    else if (a == "--height")
      args.height = std::atoi(next().c_str());
    else if (a == "--threads")
      args.threads = std::atoi(next().c_str());
    else if (a == "--supersampling")
      args.supersampling = std::atoi(next().c_str());
    else if (a == "--dir")
      args.dir = next();
    else if (a == "--profile-frames")
      args.profile_frames = std::atoi(next().c_str());
    else if (a == "--in-flight")
      args.in_flight = next();
    else if (a == "--dense-map")
      args.dense_map_voxel_m = std::atof(next().c_str());
  }
  if (args.dir.empty()) {
    std::ostringstream dir;
    dir << "/tmp/omnirig-live-loop-" << args.loop_length_m << "m-" << args.laps << "laps-"
        << args.frames << "f-" << args.width << "x" << args.height << "-ss" << args.supersampling;
    args.dir = dir.str();
  }
  return args;
}

// Renders the loop into args.dir (cam0/, cam1/, trajectory.tum, rig.json) unless it is there;
// returns the rig.
json RenderOrLoad(const BenchArgs& args) {
  const fs::path dir(args.dir);
  if (fs::exists(dir / "rig.json")) {
    std::printf("read the rendered loop from %s (delete it to render again)\n", args.dir.c_str());
    return json::parse(std::ifstream(dir / "rig.json"));
  }
  synth::StereoSequenceOptions options;
  options.environment = synth::StereoSequenceOptions::Environment::kCityBlock;
  options.path_length_m = args.loop_length_m;
  options.num_laps = args.laps;
  options.num_frames = args.frames;
  options.lighting_change = true;
  options.width = args.width;
  options.height = args.height;
  options.render.noise_sigma = 1.0;
  options.render.supersampling = args.supersampling;
  options.render.num_threads = args.threads;
  const Timer timer;
  const synth::StereoSequence sequence = synth::RenderStereoSequence(
      options,
      [&dir](int frame, const std::string& name, const cv::Mat& cam0, const cv::Mat& cam1) {
        synth::WritePng(cam0, (dir / "cam0" / (name + ".png")).string());
        synth::WritePng(cam1, (dir / "cam1" / (name + ".png")).string());
        if (frame % 100 == 0) std::fprintf(stderr, "rendered %s\n", name.c_str());
      });
  std::vector<slam::StampedPose> poses;
  for (size_t i = 0; i < sequence.world_from_rig.size(); ++i) {
    poses.push_back({sequence.timestamps_s[i], sequence.world_from_rig[i]});
  }
  slam::WriteTum(dir / "trajectory.tum", poses);
  const json rig = api::RigToJson(sequence.rig);
  std::ofstream(dir / "rig.json") << rig.dump(2);
  std::printf("rendered %d stereo frames %dx%d into %s in %.0f s (not part of the figures)\n",
              args.frames, args.width, args.height, args.dir.c_str(), timer.ElapsedSeconds());
  return rig;
}

// A relative_pose job whose result is `rig`: the render's calibration stands for a measured one.
std::string SubmitRig(server::Service& service, const json& rig) {
  api::JobType type;
  type.name = "relative_pose";
  type.validate = [](const json&) {};
  type.reads_images = false;
  type.run = [rig](const json&, const api::JobContext&) { return rig; };
  service.state().job_types.Add(type);
  auto& store = *service.state().store;
  const std::string dataset = store.CreateDataset("rig").id;
  const std::string id = store.CreateJob("relative_pose", dataset, "{}").id;
  service.state().workers->Notify();
  for (;;) {
    const auto job = store.GetJob(id);
    if (job && job->state == storage::JobState::kSucceeded) return id;
    if (job && storage::IsTerminal(job->state)) throw std::runtime_error("the rig job failed");
    store.WaitForQueueChange(0.05);  // SQLite cannot notify: a short wait between reads
  }
}

// The 1, 5 and 15 minute load averages: the machine may be shared while the bench runs.
std::string LoadAverage() {
  std::ifstream in("/proc/loadavg");
  std::string one, five, fifteen;
  in >> one >> five >> fifteen;
  return one + " " + five + " " + fifteen;
}

// The rendered frames' names (cam0/NAME, cam1/NAME), in order.
std::vector<std::string> FrameNames(const fs::path& dir) {
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir / "cam0")) {
    names.push_back(entry.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

// Where a frame's time goes: the rendered frames tracked by a slam::Session (the live job's
// tracker) in this thread, no HTTP, each `step`-th frame from the start (1: every frame, as a
// server that keeps up tracks them; larger: as one that falls behind and skips the frames
// between). Prints the mean per frame of decoding the two PNGs and of each tracking stage, and
// the keyframes among the frames; and every 10th frame the live job's snapshot: the copy the
// tracking thread takes (slam::Session::Snapshot) and the writing of trajectory.json and
// map.ply from it, which the live job's publisher does on its own thread
// (api/live_publisher.h), so that it adds nothing to a frame's latency. Returns the wall ms per
// frame of decoding and tracking.
double ProfileTracking(const BenchArgs& args, const json& rig_json, int step) {
  const fs::path dir(args.dir);
  const std::vector<std::string> names = FrameNames(dir);
  slam::SlamOptions options;
  options.num_threads = args.threads;
  slam::Session session(api::RigFromJson(rig_json), options);
  slam::StageTimes total, cpu;
  double decode_s = 0, track_s = 0, snapshot_s = 0, write_s = 0;
  int frames = 0, keyframes = 0, snapshots = 0;
  const fs::path out =
      fs::temp_directory_path() / ("omnirig-live-snapshot-" + std::to_string(::getpid()));
  fs::create_directories(out);
  std::vector<double> stamps_s;
  for (size_t i = 0; i < names.size() && frames < args.profile_frames; i += step, ++frames) {
    Timer decode;
    slam::StereoImages images;
    images.cam0 = cv::imread((dir / "cam0" / names[i]).string(), cv::IMREAD_COLOR);
    images.cam1 = cv::imread((dir / "cam1" / names[i]).string(), cv::IMREAD_COLOR);
    decode_s += decode.ElapsedSeconds();
    Timer track;
    const slam::FrameReport report = session.Track(names[i], images);
    track_s += track.ElapsedSeconds();
    total.Add(report.times);
    cpu.Add(report.cpu_times);
    keyframes += report.keyframe;
    stamps_s.push_back(0.1 * i);
    if (frames % 10 == 9) {
      Timer copy;
      const api::LiveSnapshot snapshot{session.Snapshot(), stamps_s};
      snapshot_s += copy.ElapsedSeconds();
      Timer write;
      api::WriteLiveSnapshot(session.rig(), snapshot, std::nullopt, out);
      write_s += write.ElapsedSeconds();
      ++snapshots;
    }
  }
  fs::remove_all(out);
  const auto ms = [frames](double s) { return 1000.0 * s / std::max(frames, 1); };
  std::printf(
      "every %2d. frame: %3d frames, %3d keyframes; ms per frame: decode %.1f, track %.1f = "
      "detect %.1f + stereo %.1f + match %.1f + motion %.1f + map %.1f + local BA %.1f + "
      "loop %.1f\n",
      step, frames, keyframes, ms(decode_s), ms(track_s), ms(total.detect_s), ms(total.stereo_s),
      ms(total.match_s), ms(total.motion_s), ms(total.map_s), ms(total.local_ba_s),
      ms(total.loop_s));
  std::printf(
      "                 CPU ms per frame (both threads): detect %.1f + stereo %.1f + match %.1f + "
      "motion %.1f + map %.1f + local BA %.1f + loop %.1f; load average %s\n",
      ms(cpu.detect_s), ms(cpu.stereo_s), ms(cpu.match_s), ms(cpu.motion_s), ms(cpu.map_s),
      ms(cpu.local_ba_s), ms(cpu.loop_s), LoadAverage().c_str());
  const auto per = [snapshots](double s) { return 1000.0 * s / std::max(snapshots, 1); };
  std::printf(
      "                 live snapshot every 10 frames (%d): copy %.2f ms (tracking thread), "
      "trajectory.json + map.ply written %.2f ms (publisher thread)\n",
      snapshots, per(snapshot_s), per(write_s));
  std::fflush(stdout);
  return ms(decode_s + track_s);
}

// The live job's pipeline (with 2 threads or more) in this process, no HTTP: the first
// --profile-frames frames, each decoded and through slam::Session::FrontEnd on a thread of its
// own while the frame before goes through Session::Track (its back end), as a job does when a
// frame waits whenever a back end starts. Prints the wall ms per frame against `serial_ms`, the
// same frames decoded and tracked one after the other (ProfileTracking with step 1, just before).
void ProfilePipeline(const BenchArgs& args, const json& rig_json, double serial_ms) {
  const fs::path dir(args.dir);
  const std::vector<std::string> names = FrameNames(dir);
  const int n = std::min<int>(args.profile_frames, static_cast<int>(names.size()));
  if (n == 0) return;
  slam::SlamOptions options;
  options.num_threads = args.threads;
  slam::Session session(api::RigFromJson(rig_json), options);
  const auto front_end = [&](int i) {
    slam::StereoImages images;
    images.cam0 = cv::imread((dir / "cam0" / names[i]).string(), cv::IMREAD_COLOR);
    images.cam1 = cv::imread((dir / "cam1" / names[i]).string(), cv::IMREAD_COLOR);
    return session.FrontEnd(names[i], images);
  };
  Timer wall;
  int keyframes = 0;
  std::future<slam::PreparedFrame> next = std::async(std::launch::async, front_end, 0);
  for (int i = 0; i < n; ++i) {
    slam::PreparedFrame prepared = next.get();
    if (i + 1 < n) next = std::async(std::launch::async, front_end, i + 1);
    keyframes += session.Track(std::move(prepared)).keyframe;
  }
  const double pipelined_ms = 1000.0 * wall.ElapsedSeconds() / n;
  std::printf(
      "pipelined:       %3d frames, %3d keyframes; ms per frame: %.1f (decode + front end of the "
      "next frame beside the back end of this one), serial %.1f: x%.2f; load average %s\n",
      n, keyframes, pipelined_ms, serial_ms, serial_ms / pipelined_ms, LoadAverage().c_str());
  std::fflush(stdout);
}

}  // namespace
}  // namespace omnirig

int main(int argc, char** argv) {
  omnirig::ConfigureAllocator();  // as the omnirig service runs
  using namespace omnirig;
  const BenchArgs args = Parse(argc, argv);
  const json rig = RenderOrLoad(args);
  const fs::path data =
      fs::temp_directory_path() / ("omnirig-live-bench-" + std::to_string(::getpid()));
  server::ServiceOptions options;
  options.port = 0;
  options.data_dir = data;
  options.workers.num_workers = 1;
  options.workers.threads_per_job = args.threads;
  options.min_free_bytes = 0;
  server::Service service(options);
  const int port = service.Start();
  const std::string rig_job = SubmitRig(service, rig);
  const std::time_t now = std::time(nullptr);
  char date[32];
  std::strftime(date, sizeof(date), "%Y-%m-%d", std::gmtime(&now));
  std::printf(
      "live slam through `omnirig live`, %d frames %dx%d, %d laps of %.0f m, job threads "
      "%d, measured %s\n",
      args.frames, args.width, args.height, args.laps, args.loop_length_m, args.threads, date);
  std::printf("load average before the runs (1, 5, 15 min): %s\n", LoadAverage().c_str());
  std::printf("%6s %8s %8s %9s %9s %9s %10s %11s %11s %6s %9s %8s\n", "rate", "tracked",
              "skipped", "p50 ms", "p95 ms", "p99 ms", "rt p95 ms", "c2p p50 ms", "c2p p95 ms",
              "loops", "ATE m", "ATE %");
  for (const double rate : args.rates) {
    const fs::path out = data / ("live-" + std::to_string(static_cast<int>(rate)) + ".json");
    const int code =
        cli::RunLive({"--server", "http://127.0.0.1:" + std::to_string(port), "--rig", rig_job,
                      "--rate", std::to_string(rate), "--in-flight", args.in_flight, "--params",
                      args.dense_map_voxel_m > 0
                          ? json{{"dense_map", {{"voxel_m", args.dense_map_voxel_m}}}}.dump()
                          : "{}",
                      "--json", out.string(), args.dir});
    const json s = json::parse(std::ifstream(out));
    const json e = s.value("evaluation", json());
    std::printf("%6.0f %8d %8d %9.1f %9.1f %9.1f %10.1f %11.1f %11.1f %6d %9.4f %8.3f%s\n", rate,
                s["frames_tracked"].get<int>(), s["frames_skipped"].get<int>(),
                s["latency_ms"]["p50"].get<double>(), s["latency_ms"]["p95"].get<double>(),
                s["latency_ms"]["p99"].get<double>(), s["round_trip_ms"]["p95"].get<double>(),
                s["capture_to_pose_ms"]["p50"].get<double>(),
                s["capture_to_pose_ms"]["p95"].get<double>(),
                s.value("loops", 0), e.is_object() ? e["ate_rmse_m"].get<double>() : -1.0,
                e.is_object() ? e["ate_percent_of_path"].get<double>() : -1.0,
                code == 0 ? "" : "  (job did not succeed)");
    // Where the live job's tracking time went, per tracked frame (the job's stage totals).
    const auto stored = service.state().store->GetResult(s["job"].get<std::string>());
    if (stored) {
      const json r = json::parse(*stored);
      const json t = r["timings_s"];
      const double n = std::max(1, s["frames_tracked"].get<int>());
      std::printf(
          "       %d keyframes; ms per tracked frame: detect %.1f + stereo %.1f + match %.1f + "
          "motion %.1f + map %.1f + local BA %.1f + loop %.1f; finish %.1f s; load average %s\n",
          r.value("num_keyframes", 0), 1000 * t.value("detect", 0.0) / n,
          1000 * t.value("stereo", 0.0) / n, 1000 * t.value("match", 0.0) / n,
          1000 * t.value("motion", 0.0) / n, 1000 * t.value("map", 0.0) / n,
          1000 * t.value("local_ba", 0.0) / n, 1000 * t.value("loop", 0.0) / n,
          t.value("global_ba", 0.0), LoadAverage().c_str());
      if (r.contains("dense_map") && r["dense_map"].is_object()) {
        const json& d = r["dense_map"];
        std::printf("       dense map at the finish: %d keyframes, %d points, %.1f s\n",
                    static_cast<int>(d.value("keyframes", json::array()).size()),
                    d.value("num_points", 0), d.value("seconds", 0.0));
      }
    }
    std::fflush(stdout);
  }
  if (args.profile_frames > 0) {
    const double serial_ms = ProfileTracking(args, rig, 1);
    ProfilePipeline(args, rig, serial_ms);
    ProfileTracking(args, rig, 10);
  }
  std::error_code ignored;
  fs::remove_all(data, ignored);
  return 0;
}
