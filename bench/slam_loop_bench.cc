// bench_slam --loop: SLAM on long closed loops, against their targets. The rig drives laps around
// the city block of engine/synth/city_block.h (default: a 100 m loop driven twice, 2,000 stereo
// frames at 1024x768, each lap under its own light, image noise 1 grey level).
//
// The sequence is rendered once into a cache folder (the layout of `omnirig synth --preset
// stereo-loop`: cam0/, cam1/, trajectory.tum) and read from there on later runs; the render time
// is reported apart. SLAM then runs end to end from the PNG files (decoding inside the timed run).
//
// What is measured (ground truth from trajectory.tum; the lap of frame i is laps * i / frames):
//   revisits   a frame of lap >= 1 within --revisit-m metres and --revisit-deg degrees of a
//              keyframe of an earlier lap. Since revisits tracked on the map add few keyframes,
//              recall is counted per revisit frame: recognised when the frame is localised on
//              an earlier lap's keyframe (its reference keyframe, the one sharing the most
//              landmarks with it, is of an earlier lap and truly within those bounds) or is the
//              query of a true loop to an earlier lap. Per 10 m stretch of path: stretches with
//              a revisit in which some revisit frame was recognised. Non-keyframes whose
//              reference is an earlier lap's keyframe outside those bounds are counted apart
//              (false references: their pose follows that keyframe).
//   loops      true when its two keyframes are within those bounds in ground truth; false
//              loops are the others.
//   ATE        after the run's closure and global adjustment, SE(3)-aligned, as % of the
//              distance travelled; end-point drift: the last pose's error with both
//              trajectories anchored at the first pose, as % of the distance. Before closure:
//              the first loop's correction (the drift tracking had gathered), and the same
//              figures of a run with --no-loop-closure.
//   per-frame  CPU time of the frame's stages (median over frames 90-110, or around a fifth of a
//              run shorter than 400 frames, and over the last 21), and wall; memory: the process's
//              resident set at a tenth of the run each, beside the map's growth (landmarks created
//              so far) and the keyframes so far.
//
// usage: bench_slam --loop [--loop-dir DIR] [--frames 2000] [--laps 2] [--loop-length 100]
//                   [--width 1024] [--height 768] [--threads 2] [--revisit-m 1.5]
//                   [--revisit-deg 30] [--no-loop-closure] [--supersampling 4] [--blur 0]
//                   [--max-features N] [--detection-scale S] [--local-iterations N]

#include "bench/slam_loop_bench.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "engine/slam/evaluation.h"
#include "engine/slam/map_io.h"
#include "engine/slam/slam.h"
#include "engine/synth/presets.h"
#include "engine/util/timer.h"

namespace omnirig {
namespace {

namespace fs = std::filesystem;

struct LoopArgs {
  std::string dir;  // empty: /tmp/omnirig-loop-<parameters>
  int frames = 2000;
  int laps = 2;
  double loop_length_m = 100.0;
  int width = 1024;
  int height = 768;
  int threads = 2;
  double revisit_m = 1.5;
  double revisit_deg = 30.0;
  bool loop_closure = true;
  int supersampling = 4;  // of the render
  double blur_px = 0.0;
  int max_features = -1;      // -1: the library defaults
  double detection_scale = -1;  // FeatureOptions::detection_scale; -1: the library default
  int local_iterations = -1;
};

LoopArgs ParseLoopArgs(int argc, char** argv) {
  LoopArgs args;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string { return i + 1 < argc ? argv[++i] : ""; };
    if (a == "--loop-dir") args.dir = next();
    else if (a == "--frames") args.frames = std::atoi(next().c_str());
    else if (a == "--laps") args.laps = std::atoi(next().c_str());
    else if (a == "--loop-length") args.loop_length_m = std::atof(next().c_str());
    else if (a == "--width") args.width = std::atoi(next().c_str());
    else if (a == "--height") args.height = std::atoi(next().c_str());
    else if (a == "--threads") args.threads = std::atoi(next().c_str());
    else if (a == "--revisit-m") args.revisit_m = std::atof(next().c_str());
    else if (a == "--revisit-deg") args.revisit_deg = std::atof(next().c_str());
    else if (a == "--no-loop-closure") args.loop_closure = false;
    else if (a == "--supersampling") args.supersampling = std::atoi(next().c_str());
    else if (a == "--blur") args.blur_px = std::atof(next().c_str());
    else if (a == "--max-features") args.max_features = std::atoi(next().c_str());
    else if (a == "--detection-scale") args.detection_scale = std::atof(next().c_str());
    else if (a == "--local-iterations") args.local_iterations = std::atoi(next().c_str());
  }
  if (args.dir.empty()) {
    std::ostringstream dir;
    dir << "/tmp/omnirig-loop-" << args.loop_length_m << "m-" << args.laps << "laps-"
        << args.frames << "f-" << args.width << "x" << args.height << "-ss"
        << args.supersampling << "-blur" << args.blur_px;
    args.dir = dir.str();
  }
  return args;
}

synth::StereoSequenceOptions SequenceOptions(const LoopArgs& args) {
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
  options.render.blur_sigma_px = args.blur_px;
  options.render.num_threads = args.threads;
  return options;
}

double ProcessCpuSeconds() {
  timespec ts;
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

double ResidentMegabytes() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;
  }
  return 0.0;
}

// trajectory.tum: "timestamp tx ty tz qx qy qz qw" per frame, world_from_rig.
void WriteTum(const synth::StereoSequence& sequence, const fs::path& path) {
  std::vector<slam::StampedPose> poses;
  for (size_t i = 0; i < sequence.world_from_rig.size(); ++i) {
    poses.push_back({sequence.timestamps_s[i], sequence.world_from_rig[i]});
  }
  slam::WriteTum(path, poses);
}

// Renders the sequence into args.dir unless it holds it already; returns the frame names.
std::vector<std::string> RenderOrLoad(const LoopArgs& args, std::vector<Rigid3d>* truth) {
  const fs::path dir(args.dir);
  if (!fs::exists(dir / "trajectory.tum")) {
    fs::create_directories(dir / "cam0");
    fs::create_directories(dir / "cam1");
    const Timer timer;
    const double cpu_start = ProcessCpuSeconds();
    const synth::StereoSequence sequence = synth::RenderStereoSequence(
        SequenceOptions(args),
        [&dir](int frame, const std::string& name, const cv::Mat& cam0, const cv::Mat& cam1) {
          synth::WritePng(cam0, (dir / "cam0" / (name + ".png")).string());
          synth::WritePng(cam1, (dir / "cam1" / (name + ".png")).string());
          if (frame % 100 == 0) std::fprintf(stderr, "rendered %s\n", name.c_str());
        });
    WriteTum(sequence, dir / "trajectory.tum");
    std::printf("rendered %d stereo frames %dx%d into %s in %.0f s wall, %.0f s CPU (%.2f s CPU "
                "per stereo frame; not part of the figures below)\n",
                args.frames, args.width, args.height, args.dir.c_str(), timer.ElapsedSeconds(),
                ProcessCpuSeconds() - cpu_start, (ProcessCpuSeconds() - cpu_start) / args.frames);
  } else {
    std::printf("read the rendered sequence from %s (delete it to render again)\n",
                args.dir.c_str());
  }
  truth->clear();
  for (const slam::StampedPose& pose : slam::ReadTum(dir / "trajectory.tum")) {
    truth->push_back(pose.world_from_rig);
  }
  std::vector<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir / "cam0")) {
    if (entry.path().extension() == ".png") names.push_back(entry.path().stem().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

// What the SLAM result says about keyframes and loops (SlamResult::loops,
// FrameReport::keyframe): the one place that reads them.
struct LoopView {
  std::vector<bool> keyframe;
  std::vector<int> reference_keyframe;     // per frame, -1: none
  std::vector<std::pair<int, int>> loops;  // (frame index, matched frame index)
};

LoopView ReadLoops(const slam::SlamResult& result) {
  LoopView view;
  for (const slam::FrameReport& frame : result.frames) {
    view.keyframe.push_back(frame.keyframe);
    view.reference_keyframe.push_back(frame.world_from_rig ? frame.reference_keyframe : -1);
  }
  for (const slam::LoopReport& loop : result.loops) {
    view.loops.emplace_back(loop.frame_index, loop.matched_frame_index);
  }
  return view;
}

double AngleDeg(const Rigid3d& a, const Rigid3d& b) {
  return a.rotation.angularDistance(b.rotation) * 180.0 / M_PI;
}

struct LoopFigures {
  int revisit_frames = 0, revisit_frames_found = 0;
  int revisit_stretches = 0, revisit_stretches_found = 0;
  int false_references = 0;  // non-keyframes referenced to an earlier lap's keyframe not near it
  int true_loops = 0, false_loops = 0;
  // The false ones: matched to a keyframe of the same lap or of an earlier one, and the largest
  // ground-truth distance between a false loop's keyframes.
  int false_same_lap = 0, false_earlier_lap = 0;
  double false_max_distance_m = 0.0;
  int first_revisit_loop = -1;  // index into the loops of the first true loop to an earlier lap
};

LoopFigures CountLoops(const LoopArgs& args, const LoopView& view,
                       const std::vector<Rigid3d>& truth) {
  const int n = static_cast<int>(truth.size());
  auto lap = [&](int i) { return std::min(args.laps - 1, args.laps * i / n); };
  auto near = [&](int i, int j) {
    return (truth[i].translation - truth[j].translation).norm() <= args.revisit_m &&
           AngleDeg(truth[i], truth[j]) <= args.revisit_deg;
  };
  // The 10 m stretch of the loop that frame i is on, per lap.
  auto stretch = [&](int i) {
    const double s = args.laps * args.loop_length_m * i / n;
    return lap(i) * 1000 + static_cast<int>(std::fmod(s, args.loop_length_m) / 10.0);
  };
  LoopFigures figures;
  std::set<int> revisit_loop_frames, stretches_with_revisit, stretches_found;
  for (size_t l = 0; l < view.loops.size(); ++l) {
    const auto& [frame, matched] = view.loops[l];
    if (near(frame, matched)) {
      ++figures.true_loops;
      if (lap(matched) < lap(frame)) {
        revisit_loop_frames.insert(frame);
        if (figures.first_revisit_loop < 0) figures.first_revisit_loop = static_cast<int>(l);
      }
    } else {
      ++figures.false_loops;
      ++(lap(matched) < lap(frame) ? figures.false_earlier_lap : figures.false_same_lap);
      figures.false_max_distance_m = std::max(
          figures.false_max_distance_m, (truth[frame].translation - truth[matched].translation).norm());
    }
  }
  std::vector<int> keyframes;
  for (int j = 0; j < n; ++j) {
    if (view.keyframe[j]) keyframes.push_back(j);
  }
  for (int k = 0; k < n; ++k) {
    if (lap(k) == 0) continue;
    const int reference = view.reference_keyframe[k];
    const bool earlier_reference = reference >= 0 && lap(reference) < lap(k);
    // A keyframe's reference may be far (that is why it became one: the previous keyframe
    // across a lap's end, say); a non-keyframe's pose follows its reference.
    if (earlier_reference && !view.keyframe[k] && !near(k, reference)) {
      ++figures.false_references;
      std::printf("false reference: frame %d -> keyframe %d, %.2f m, %.1f deg apart (truth)\n", k,
                  reference, (truth[k].translation - truth[reference].translation).norm(),
                  AngleDeg(truth[k], truth[reference]));
    }
    bool revisit = false;
    for (size_t j = 0; j < keyframes.size() && !revisit; ++j) {
      revisit = lap(keyframes[j]) < lap(k) && near(k, keyframes[j]);
    }
    if (!revisit) continue;
    ++figures.revisit_frames;
    stretches_with_revisit.insert(stretch(k));
    if ((earlier_reference && near(k, reference)) || revisit_loop_frames.count(k) > 0) {
      ++figures.revisit_frames_found;
      stretches_found.insert(stretch(k));
    }
  }
  figures.revisit_stretches = static_cast<int>(stretches_with_revisit.size());
  for (const int s : stretches_with_revisit) figures.revisit_stretches_found += stretches_found.count(s);
  return figures;
}

// Per lap: keyframes made, and the local adjustments' mean free and fixed poses and CPU per
// frame (the window must not grow with the laps).
void PrintPerLap(const LoopArgs& args, const slam::SlamResult& result) {
  const int n = static_cast<int>(result.frames.size());
  std::printf("\n%4s %10s %10s %12s %12s %16s\n", "lap", "keyframes", "local BAs", "free poses",
              "fixed poses", "local BA ms/frame");
  for (int lap = 0; lap < args.laps; ++lap) {
    int keyframes = 0, adjustments = 0;
    double free_poses = 0, fixed_poses = 0, cpu_s = 0;
    const int first = lap * n / args.laps, last = (lap + 1) * n / args.laps;
    for (int i = first; i < last; ++i) {
      const slam::FrameReport& f = result.frames[i];
      keyframes += f.keyframe;
      cpu_s += f.cpu_times.local_ba_s;
      if (!f.local_bundle_adjustment) continue;
      ++adjustments;
      free_poses += f.local_bundle_adjustment->num_free_poses;
      fixed_poses += f.local_bundle_adjustment->num_constant_poses;
    }
    std::printf("%4d %10d %10d %12.1f %12.1f %16.1f\n", lap + 1, keyframes, adjustments,
                adjustments ? free_poses / adjustments : 0.0,
                adjustments ? fixed_poses / adjustments : 0.0,
                1e3 * cpu_s / std::max(1, last - first));
  }
}

double MedianOver(const slam::SlamResult& result, int first, int last, bool cpu) {
  std::vector<double> values;
  for (int i = std::max(0, first); i <= last && i < static_cast<int>(result.frames.size()); ++i) {
    const slam::FrameReport& f = result.frames[i];
    values.push_back(cpu ? f.cpu_times.Total() : f.times.Total());
  }
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

struct MemorySample {
  int frame = 0;
  double rss_mb = 0.0;
};

void PrintTrajectory(const LoopArgs& args, const slam::SlamResult& result,
                     const std::vector<Rigid3d>& truth) {
  std::vector<Rigid3d> estimate, gt;
  int lap_end = -1;  // the last frame of the first lap with a pose
  for (size_t i = 0; i < result.frames.size(); ++i) {
    if (!result.frames[i].world_from_rig) continue;
    estimate.push_back(*result.frames[i].world_from_rig);
    gt.push_back(truth[i]);
    if (static_cast<int>(i) < static_cast<int>(truth.size()) / args.laps) {
      lap_end = static_cast<int>(estimate.size()) - 1;
    }
  }
  if (estimate.size() < 2) {
    std::printf("fewer than two poses: no trajectory figures\n");
    return;
  }
  const slam::TrajectoryErrors errors = slam::EvaluateTrajectory(estimate, gt);
  std::printf("%-52s %12.1f %12s\n", "distance travelled (m)", errors.path_length_m, "");
  std::printf("%-52s %12.4f %12s\n", "ATE RMSE after closure (m)", errors.ate_rmse_m, "");
  std::printf("%-52s %12.4f %12s\n", "ATE RMSE after closure (% of distance)",
              100.0 * errors.ate_rmse_m / errors.path_length_m, "<= 0.1");
  std::printf("%-52s %12.3f %12s\n", "end-point drift, last pose (% of distance)",
              errors.final_drift_percent, "reported");
  if (lap_end >= 1) {
    const std::vector<Rigid3d> lap_estimate(estimate.begin(), estimate.begin() + lap_end + 1);
    const std::vector<Rigid3d> lap_gt(gt.begin(), gt.begin() + lap_end + 1);
    std::printf("%-52s %12.3f %12s\n", "drift at the end of lap 1 (% of distance)",
                slam::EvaluateTrajectory(lap_estimate, lap_gt).final_drift_percent, "reported");
  }
}

}  // namespace

int RunLoopBench(int argc, char** argv) {
  const LoopArgs args = ParseLoopArgs(argc, argv);
  std::vector<Rigid3d> truth;
  const std::vector<std::string> names = RenderOrLoad(args, &truth);
  if (names.size() != truth.size() || names.empty()) {
    std::fprintf(stderr, "%s: %zu images but %zu poses\n", args.dir.c_str(), names.size(),
                 truth.size());
    return 1;
  }
  const int n = static_cast<int>(names.size());
  StereoRig rig;
  rig.cam0 = synth::DefaultCamera(args.width, args.height).model;
  rig.cam1 = synth::DefaultSecondCamera(args.width, args.height).model;
  rig.cam0_from_cam1 = synth::DefaultCam0FromCam1();

  std::vector<MemorySample> memory;
  const fs::path dir(args.dir);
  auto load = [&](int i) {
    if (i % std::max(1, n / 10) == 0 || i == n - 1) memory.push_back({i, ResidentMegabytes()});
    return slam::ReadBoth([&](int c) {
      return cv::imread((dir / ("cam" + std::to_string(c)) / (names[i] + ".png")).string(),
                        cv::IMREAD_COLOR);
    });
  };
  slam::SlamOptions options;
  options.num_threads = args.threads;
  options.loop_closure = args.loop_closure;
  if (args.max_features >= 0) options.features.max_features = args.max_features;
  if (args.detection_scale > 0) options.features.detection_scale = args.detection_scale;
  if (args.local_iterations > 0) options.local_max_iterations = args.local_iterations;
  const double rss_before_mb = ResidentMegabytes();
  const slam::SlamResult result = slam::RunSlam(rig, names, load, options);

  const LoopView view = ReadLoops(result);
  std::printf("\n%d stereo frames %dx%d, %d laps of %.0f m; %d tracked, %d lost, %d keyframes\n",
              n, args.width, args.height, args.laps, args.loop_length_m, result.num_tracked,
              result.num_lost, result.num_keyframes);
  std::map<std::string, int> states;
  for (const slam::FrameReport& frame : result.frames) ++states[frame.state];
  for (const auto& [state, count] : states) std::printf("  %s: %d\n", state.c_str(), count);
  std::printf("\n%-52s %12s %12s\n", "metric", "measured", "target");
  const LoopFigures loops = CountLoops(args, view, truth);
  if (!options.loop_closure) std::printf("(loop closure off: --no-loop-closure)\n");
  std::printf("%-52s %6d / %-5d %12s\n", "revisit frames recognised", loops.revisit_frames_found,
              loops.revisit_frames, "");
  std::printf(
      "%-52s %12.1f %12s\n", "recall per revisit frame (%)",
      loops.revisit_frames ? 100.0 * loops.revisit_frames_found / loops.revisit_frames : 0.0,
      ">= 90");
  std::printf("%-52s %12.1f %12s\n", "recall per revisited 10 m stretch (%)",
              loops.revisit_stretches ? 100.0 * loops.revisit_stretches_found / loops.revisit_stretches : 0.0,
              ">= 90");
  std::printf("%-52s %12d %12s\n", "true loops accepted", loops.true_loops, "");
  std::printf("%-52s %12d %12s\n", "false loops accepted", loops.false_loops, "0");
  std::printf("%-52s %12d %12s\n", "false references (non-keyframes, earlier lap, far)",
              loops.false_references, "0");
  std::printf("%-52s %5d / %-6d %12s\n", "  of which to the same lap / an earlier lap",
              loops.false_same_lap, loops.false_earlier_lap, "");
  std::printf("%-52s %12.2f %12s\n", "  largest distance between their keyframes (m)",
              loops.false_max_distance_m, "");
  if (loops.first_revisit_loop >= 0) {
    // The correction of the first loop to an earlier lap is the drift tracking had gathered
    // until it closed.
    const slam::LoopReport& first = result.loops[loops.first_revisit_loop];
    const double travelled_m = args.laps * args.loop_length_m * first.frame_index / n;
    std::printf("%-52s %12.3f %12s\n", "first revisit loop's correction (% of distance)",
                100.0 * first.correction_m / travelled_m, "reported");
    std::printf("  first loop: %s -> %s, %d inliers, %.3f m, %.3f deg, after %.1f m\n",
                first.frame.c_str(), first.matched_frame.c_str(), first.inliers,
                first.correction_m, first.correction_deg, travelled_m);
  }
  PrintTrajectory(args, result, truth);
  std::printf("%-52s %12d %12s\n", "keyframes", result.num_keyframes, "");
  PrintPerLap(args, result);
  std::printf("\n%8s %8s %8s %10s %10s %6s %10s\n", "frame", "matched", "inliers", "corr (m)",
              "corr (deg)", "graph", "truth (m)");
  for (const slam::LoopReport& loop : result.loops) {
    std::printf("%8d %8d %8d %10.3f %10.3f %6s %10.2f\n", loop.frame_index,
                loop.matched_frame_index, loop.inliers, loop.correction_m, loop.correction_deg,
                loop.pose_graph ? "yes" : "no",
                (truth[loop.frame_index].translation - truth[loop.matched_frame_index].translation)
                    .norm());
  }
  for (const slam::FrameReport& f : result.frames) {
    if (f.state != "tracked") std::printf("frame %s: %s %s\n", f.name.c_str(), f.state.c_str(), f.reason.c_str());
  }
  const slam::StageTimes& c = result.cpu_stage_totals;
  std::printf("CPU s: load %.1f detect %.1f stereo %.1f match %.1f motion %.1f map %.1f local BA %.1f "
              "loop %.1f global BA %.1f\n", c.load_s, c.detect_s, c.stereo_s, c.match_s, c.motion_s,
              c.map_s, c.local_ba_s, c.loop_s, result.global_ba_cpu_s);
  std::printf("CPU ms per frame: load %.1f detect %.1f stereo %.1f match %.1f motion %.1f map %.1f "
              "local BA %.1f loop %.1f global BA %.1f\n", 1e3 * c.load_s / n, 1e3 * c.detect_s / n,
              1e3 * c.stereo_s / n, 1e3 * c.match_s / n, 1e3 * c.motion_s / n, 1e3 * c.map_s / n,
              1e3 * c.local_ba_s / n, 1e3 * c.loop_s / n, 1e3 * result.global_ba_cpu_s / n);

  // Frames 90-110 (on short runs, the 21 frames around a fifth of the run) against the last 21.
  const int early = n >= 400 ? 100 : n / 5;
  const double early_cpu = MedianOver(result, early - 10, early + 10, true);
  const double late_cpu = MedianOver(result, n - 21, n - 1, true);
  const std::string early_label =
      "CPU per frame, median of frames " + std::to_string(std::max(0, early - 10)) + "-" +
      std::to_string(early + 10) + " (s)";
  std::printf("%-52s %12.3f %12s\n", early_label.c_str(), early_cpu, "");
  std::printf("%-52s %12.3f %12s\n", "CPU per frame, median of the last 21 frames (s)", late_cpu,
              "");
  std::printf("%-52s %12.2f %12s\n", "late / early CPU per frame", late_cpu / early_cpu, "<= 1.2");
  std::printf("%-52s %12.2f %12s\n", "late / early wall per frame",
              MedianOver(result, n - 21, n - 1, false) /
                  MedianOver(result, early - 10, early + 10, false),
              "");
  std::printf("%-52s %12.2f %12s\n", "frames per second, end to end", n / result.total_s, ">= 8");
  std::printf("%-52s %12.3f %12s\n", "CPU per frame, whole run incl. global BA (s)",
              result.total_cpu_s / n, "");
  std::printf("%-52s %12.1f %12s\n", "global bundle adjustment (s)", result.global_ba_s, "");
  std::printf("%-52s %12zu %12s\n", "map points (exported)", result.map.size(), "");

  std::printf("\n%8s %10s %14s %10s\n", "frame", "RSS (MB)", "landmarks made", "keyframes");
  std::printf("%8s %10.0f %14s %10s\n", "start", rss_before_mb, "", "");
  for (const MemorySample& sample : memory) {
    long landmarks = 0, keyframes = 0;
    for (int i = 0; i <= sample.frame && i < static_cast<int>(result.frames.size()); ++i) {
      landmarks += result.frames[i].num_new_landmarks;
      keyframes += view.keyframe[i];
    }
    std::printf("%8d %10.0f %14ld %10ld\n", sample.frame, sample.rss_mb, landmarks, keyframes);
  }
  if (FILE* f = std::fopen("/proc/loadavg", "r")) {
    double load1 = 0;
    if (std::fscanf(f, "%lf", &load1) == 1) std::printf("load average (1 min) at the end: %.2f\n", load1);
    std::fclose(f);
  }
  return 0;
}

}  // namespace omnirig
