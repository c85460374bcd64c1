// bench_slam: stereo omnidirectional SLAM on the synthetic textured-room sequence (the
// targets: drift under 1% of the distance travelled over 40 frames / ~6 m, map points' median
// distance to the true surfaces under 1% of their range, >= 5 stereo frames/s at 1024x768 on
// 2 cores end to end, global bundle adjustment under 1 s). Renders the sequence first (not
// timed), then runs SLAM on the in-memory images and prints a table.
//
// End to end means from encoded images to the trajectory: the frames are PNG-encoded in memory
// beforehand (as `omnirig synth` writes them) and decoded by the loader inside the timed run
// (--no-decode hands SLAM the rendered images instead). With --video mp4|avi|mkv the frames are
// written as cam0.EXT and cam1.EXT (mp4v, MJPG or lossless FFV1, as `omnirig synth --video`)
// before the timed run, which then pairs their timestamps (one pass, reported apart) and decodes
// them frame by frame (engine/slam/video_source.h).
//
// After the timed run, two untimed ones with a wrong calibration (slam::PerturbedCalibration:
// focal +0.5 %, principal points 1-1.5 px off, cam1 turned 0.2 deg; the stereo gate widened
// to 0.02 rad for both), without and with the global adjustment's calibration refinement
// (--no-calibration-runs skips them).
//
// --dense-map: after the timed run, the dense map of the slam job's "dense_map" is
// fused along the estimated trajectory with the same loader (PNG decode included), timed in wall
// and CPU seconds against the SLAM run's (target: at most 30 % added to the job's wall time),
// and scored against the room (median distance to the true surfaces <= 0.5 % of range,
// occupancy agreeing in >= 95 % of the observed cells). --grid-step-factor and
// --keyframe-spacing set DenseMapOptions' fields of the same names.
// bench_slam --loop ...: the long closed-loop bench instead (bench/slam_loop_bench.cc).
//
// usage: bench_slam [--frames N] [--width W] [--height H] [--threads T] [--street]
//                   [--max-features N] [--detection-scale S] [--local-window N]
//                   [--local-iterations N] [--no-decode]
//                   [--black-frame I] [--no-calibration-runs] [--video mp4|avi|mkv]
//                   [--dense-map [--grid-step-factor F] [--keyframe-spacing M]]

#include <unistd.h>
#include <algorithm>
#include <array>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <ctime>
#include <string>
#include <vector>

#include <filesystem>
#include <memory>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "bench/slam_loop_bench.h"
#include "engine/dense/dense_map.h"
#include "engine/slam/evaluation.h"
#include "engine/slam/slam.h"
#include "engine/slam/video_source.h"
#include "engine/synth/presets.h"
#include "engine/util/allocator.h"
#include "engine/util/timer.h"
#include "testing/dense/map_accuracy.h"
#include "testing/slam/sequence_accuracy.h"
#include "testing/slam/surface_distance.h"

namespace omnirig {
namespace {

struct Args {
  int frames = 40;
  int width = 1024;
  int height = 768;
  int threads = 2;
  bool street = false;
  bool decode = true;
  int max_features = -1;  // -1: the library defaults
  double detection_scale = -1;  // FeatureOptions::detection_scale; -1: the library default
  int local_window = -1;
  int local_iterations = -1;
  int black_frame = -1;  // this frame's cam0 image is replaced by a black one (tracking loss)
  bool calibration_runs = true;
  std::string video;  // "", "mp4", "avi", "mkv"
  bool dense_map = false;
  // Each combination is fused and scored after the one SLAM run; empty: the library defaults.
  std::vector<double> grid_step_factors;
  std::vector<double> keyframe_spacings_m;
};

// "1,1.5,2" -> {1, 1.5, 2}.
std::vector<double> Numbers(const std::string& list) {
  std::vector<double> values;
  size_t start = 0;
  while (start <= list.size()) {
    const size_t end = std::min(list.find(',', start), list.size());
    values.push_back(std::atof(list.substr(start, end - start).c_str()));
    start = end + 1;
  }
  return values;
}

Args ParseArgs(int argc, char** argv) {
  Args args;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() { return i + 1 < argc ? std::atoi(argv[++i]) : 0; };
    if (a == "--frames") args.frames = next();
    else if (a == "--width") args.width = next();
    else if (a == "--height") args.height = next();
    else if (a == "--threads") args.threads = next();
    else if (a == "--street") args.street = true;
    else if (a == "--no-decode") args.decode = false;
    else if (a == "--black-frame") args.black_frame = next();
    else if (a == "--no-calibration-runs") args.calibration_runs = false;
    else if (a == "--video" && i + 1 < argc)
      args.video = argv[++i];
    else if (a == "--dense-map") args.dense_map = true;
    else if (a == "--grid-step-factor" && i + 1 < argc)
      args.grid_step_factors = Numbers(argv[++i]);
    else if (a == "--keyframe-spacing" && i + 1 < argc)
      args.keyframe_spacings_m = Numbers(argv[++i]);
    else if (a == "--max-features") args.max_features = next();
    else if (a == "--detection-scale" && i + 1 < argc)
      args.detection_scale = std::atof(argv[++i]);
    else if (a == "--local-window") args.local_window = next();
    else if (a == "--local-iterations") args.local_iterations = next();
  }
  return args;
}

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}

// The dense map along the estimated trajectory, timed against the SLAM run and scored.
void DenseMapRun(const Args& args, const synth::StereoSequence& sequence,
                 const slam::StereoFrameLoader& load, const slam::SlamResult& result,
                 double slam_cpu_s, const dense::DenseMapOptions& options) {
  dense::DenseMap map(options);
  std::vector<std::optional<Rigid3d>> world_from_rig;
  for (const slam::FrameReport& frame : result.frames) {
    world_from_rig.push_back(frame.world_from_rig);
  }
  const Timer timer;
  const std::clock_t cpu_start = std::clock();
  const dense::KeyframeFusionReport fusion = dense::FuseKeyframes(
      sequence.rig, world_from_rig,
      [&](int i) {
        const slam::StereoImages images = load(i);
        return std::array<cv::Mat, 2>{images.cam0, images.cam1};
      },
      args.threads, ProgressSink(), &map);
  const PlyCloud cloud = map.Cloud();
  const dense::OccupancyGrid grid = map.Occupancy();
  const double wall_s = timer.ElapsedSeconds();
  const double cpu_s = static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC;
  if (fusion.keyframes.empty() || !world_from_rig[fusion.keyframes[0]]) return;
  // The map's world is the estimate's: into the scene's by the first keyframe's alignment.
  const int first = fusion.keyframes[0];
  const Rigid3d true_from_map = sequence.world_from_rig[first] * world_from_rig[first]->Inverse();
  std::vector<Eigen::Vector3d> keyframes_in_scene;
  for (int i : fusion.keyframes) {
    keyframes_in_scene.push_back(sequence.world_from_rig[i].translation);
  }
  const dense::DenseMapAccuracy accuracy =
      dense::EvaluateDenseMap(sequence.scene, true_from_map, keyframes_in_scene, map);
  std::printf("\ndense map (voxel %.3f m, grid step factor %.2f, keyframe spacing %.2f m): %zu "
              "keyframes, %d points\n",
              options.voxel_m, options.grid_step_factor, options.keyframe_spacing_m,
              fusion.keyframes.size(), accuracy.num_points);
  std::printf("  wall: rectification tables %.3f s, keyframes' dense stereo %.3f s, fusion %.3f s, "
              "total with cloud + occupancy %.3f s = %.1f %% of SLAM's %.3f s (target <= 30 %%)\n",
              fusion.setup_s, fusion.stereo_s, fusion.fusion_s, wall_s,
              100.0 * wall_s / result.total_s, result.total_s);
  std::printf("  CPU: %.3f s = %.1f %% of SLAM's %.3f s\n", cpu_s, 100.0 * cpu_s / slam_cpu_s,
              slam_cpu_s);
  std::printf("  accuracy: median distance to the surfaces %.3f %% of range (target <= 0.5), "
              "%.1f %% within 1 %%; occupancy %.1f %% of %d observed cells agree (target >= 95), "
              "%d occupied (%d wrongly); floor %.3f m below the first frame, %zu voxels kept\n",
              100 * accuracy.median_relative, 100 * accuracy.within_1_percent,
              100 * accuracy.agreement, accuracy.num_known_cells, accuracy.num_occupied_cells,
              accuracy.num_false_occupied_cells, grid.floor_height_m, cloud.size());
}

// The untimed runs with PerturbedCalibration, without and with refinement: one table row each.
void CalibrationRuns(const Args& args, const synth::StereoSequence& sequence,
                     const slam::StereoFrameLoader& load) {
  std::printf("\nwrong calibration (focal +0.5 %%, principal points 1-1.5 px, cam1 turned 0.2 deg; "
              "stereo gate 0.02 rad), not timed; calibration error = RMS px over the mirror "
              "vs the renderer's:\n");
  std::printf("%-10s %9s %9s %9s %9s %9s %9s %9s %9s %8s %6s\n", "refine", "applied",
              "cam0 px", "cam1 px", "rig deg", "BA rms", "drift %", "ATE m", "map %rng", "BA s",
              "BA it");
  const StereoRig given = slam::PerturbedCalibration(sequence.rig);
  for (slam::CalibrationRefinement refine :
       {slam::CalibrationRefinement::kNone, slam::CalibrationRefinement::kAll}) {
    slam::SlamOptions options;
    options.num_threads = args.threads;
    options.stereo.max_epipolar_error_rad = 0.02;
    options.calibration_refinement.refine = refine;
    const slam::SlamResult result = slam::RunSlam(given, sequence.names, load, options);
    const bool applied = result.calibration_refinement && result.calibration_refinement->applied;
    const slam::SequenceAccuracy accuracy = slam::EvaluateOnSequence(
        sequence, result, applied ? result.calibration_refinement->after : given);
    std::printf(
        "%-10s %9s %9.3f %9.3f %9.4f %9.3f %9.3f %9.4f %9.3f %8.3f %6d\n",
        slam::CalibrationRefinementName(refine), applied ? "yes" : "no",
        accuracy.calibration_rms_px[0], accuracy.calibration_rms_px[1],
        accuracy.rig_rotation_error_deg,
        result.global_bundle_adjustment ? result.global_bundle_adjustment->final_rms_px : 0.0,
        accuracy.trajectory.final_drift_percent, accuracy.trajectory.ate_rmse_m,
        accuracy.map_median_percent_of_range, result.global_ba_s,
        result.global_bundle_adjustment ? result.global_bundle_adjustment->solver.num_iterations
                                        : 0);
    if (result.calibration_refinement && !applied) {
      std::printf("  not refined: %s\n", result.calibration_refinement->reason.c_str());
    }
  }
}

// Writes the sequence as DIR/cam0.EXT and DIR/cam1.EXT at 1 / frame interval frames/s.
slam::StereoVideoFiles WriteVideos(const synth::StereoSequence& sequence, const std::string& format,
                                   const std::filesystem::path& dir) {
  std::filesystem::create_directories(dir);
  const int fourcc = format == "mkv"   ? cv::VideoWriter::fourcc('F', 'F', 'V', '1')
                     : format == "avi" ? cv::VideoWriter::fourcc('M', 'J', 'P', 'G')
                                       : cv::VideoWriter::fourcc('m', 'p', '4', 'v');
  const double fps = 1.0 / (sequence.timestamps_s[1] - sequence.timestamps_s[0]);
  slam::StereoVideoFiles files{dir / ("cam0." + format), dir / ("cam1." + format)};
  for (int c = 0; c < 2; ++c) {
    cv::VideoWriter writer((c == 0 ? files.cam0 : files.cam1).string(), cv::CAP_FFMPEG, fourcc, fps,
                           sequence.images[c][0].size());
    for (const cv::Mat& image : sequence.images[c]) writer.write(image);
  }
  return files;
}

int Run(const Args& args) {
  synth::StereoSequenceOptions sequence_options;
  sequence_options.num_frames = args.frames;
  sequence_options.width = args.width;
  sequence_options.height = args.height;
  sequence_options.render.noise_sigma = 1.0;
  if (args.street) sequence_options.environment = synth::StereoSequenceOptions::Environment::kStreet;
  const Timer render_timer;
  synth::StereoSequence sequence = synth::MakeStereoSequence(sequence_options);
  if (args.black_frame >= 0 && args.black_frame < args.frames) {
    sequence.images[0][args.black_frame].setTo(cv::Scalar::all(0));
  }
  std::printf("rendered %d stereo frames %dx%d in %.1f s (not timed below)\n", args.frames,
              args.width, args.height, render_timer.ElapsedSeconds());

  std::vector<std::vector<uchar>> png[2];
  if (args.decode) {
    for (int c = 0; c < 2; ++c) {
      for (const cv::Mat& image : sequence.images[c]) {
        png[c].emplace_back();
        cv::imencode(".png", image, png[c].back());
      }
    }
  }
  auto decoded_load = [&](int i) {
    if (!args.decode) return slam::StereoImages{sequence.images[0][i], sequence.images[1][i]};
    // As the job's loader: the two images decoded side by side.
    return slam::ReadBoth([&](int c) { return cv::imdecode(png[c][i], cv::IMREAD_COLOR); });
  };

  std::unique_ptr<slam::StereoVideoReader> reader;
  slam::StereoVideoFiles video_files;
  if (!args.video.empty()) {
    video_files = WriteVideos(sequence, args.video,
                              std::filesystem::temp_directory_path() /
                                  ("omnirig_bench_slam_" + std::to_string(::getpid())));
    std::printf("wrote %s and %s (%.1f + %.1f MB)\n", video_files.cam0.c_str(),
                video_files.cam1.c_str(), std::filesystem::file_size(video_files.cam0) / 1e6,
                std::filesystem::file_size(video_files.cam1) / 1e6);
  }
  const std::clock_t cpu_start = std::clock();
  if (!args.video.empty()) {
    const Timer pass_timer;
    const std::clock_t pass_cpu_start = std::clock();
    reader = std::make_unique<slam::StereoVideoReader>(
        video_files, slam::PairStereoVideoFrames(video_files, slam::VideoFrameOptions()));
    std::printf("timestamp pass (read + pair every frame's time): %.3f s wall, %.3f s CPU\n",
                pass_timer.ElapsedSeconds(),
                static_cast<double>(std::clock() - pass_cpu_start) / CLOCKS_PER_SEC);
  }
  const slam::StereoFrameLoader load = [&](int i) {
    if (reader) return reader->Load(i);
    return decoded_load(i);
  };
  slam::SlamOptions options;
  options.num_threads = args.threads;
  if (args.max_features >= 0) options.features.max_features = args.max_features;
  if (args.detection_scale > 0) options.features.detection_scale = args.detection_scale;
  if (args.local_window >= 0) options.local_window_frames = args.local_window;
  if (args.local_iterations > 0) options.local_max_iterations = args.local_iterations;
  const slam::SlamResult result = slam::RunSlam(sequence.rig, sequence.names, load, options);

  const double cpu_s = static_cast<double>(std::clock() - cpu_start) / CLOCKS_PER_SEC;
  std::printf("\n%-10s %-13s %6s %6s %6s %6s %6s %6s %6s  %s\n", "frame", "state", "feat0",
              "feat1", "stereo", "match", "E_inl", "s_inl", "track", "motion / reason");
  for (const slam::FrameReport& f : result.frames) {
    std::printf("%-10s %-13s %6d %6d %6d %6d %6d %6d %6d  %s%s\n", f.name.c_str(),
                f.state.c_str(), f.num_features[0], f.num_features[1], f.num_stereo_points,
                f.num_matches, f.num_essential_inliers, f.num_scale_inliers,
                f.num_tracked_landmarks, f.motion_source.c_str(), f.reason.c_str());
  }

  std::vector<Rigid3d> estimate, truth;
  for (size_t i = 0; i < result.frames.size(); ++i) {
    if (!result.frames[i].world_from_rig) continue;
    estimate.push_back(*result.frames[i].world_from_rig);
    truth.push_back(sequence.world_from_rig[i]);
  }
  std::printf("\n%-44s %12s %12s\n", "metric", "measured", "target");
  std::printf("%-44s %12d %12d\n", "frames tracked", result.num_tracked, args.frames);
  std::printf("%-44s %12d %12s\n", "keyframes", result.num_keyframes, "");
  std::printf("%-44s %12zu %12s\n", "loops (verified)", result.loops.size(), "");
  if (estimate.size() >= 2) {
    const slam::TrajectoryErrors errors = slam::EvaluateTrajectory(estimate, truth);
    std::printf("%-44s %12.3f %12s\n", "path length (m)", errors.path_length_m, "~6");
    std::printf("%-44s %12.3f %12s\n", "drift, final (% of distance)", errors.final_drift_percent, "< 1");
    std::printf("%-44s %12.3f %12s\n", "drift, max past 25% of path (%)", errors.max_drift_percent, "");
    std::printf("%-44s %12.4f %12s\n", "ATE RMSE after SE(3) alignment (m)", errors.ate_rmse_m, "");
    std::printf("%-44s %12.4f %12s\n", "RPE translation RMSE (m/frame)", errors.rpe_translation_rmse_m, "");
    std::printf("%-44s %12.4f %12s\n", "RPE rotation RMSE (deg/frame)", errors.rpe_rotation_rmse_deg, "");
    // Map accuracy: each point's distance to the true surfaces, relative to its range from
    // the nearest rig position that observed... (the first frame's pose is the world anchor,
    // so points are moved into the ground truth's world with the first-pose alignment).
    const Rigid3d gt_from_estimate = truth.front() * estimate.front().Inverse();
    std::vector<double> relative, absolute;
    for (const slam::MapPoint& point : result.map) {
      const Eigen::Vector3d p = gt_from_estimate * point.point_in_world;
      double range = 1e9;
      for (const Rigid3d& pose : truth) range = std::min(range, (p - pose.translation).norm());
      const double d = slam::DistanceToSceneSurface(sequence.scene, p);
      absolute.push_back(d);
      relative.push_back(100.0 * d / range);
    }
    std::printf("%-44s %12zu %12s\n", "map points", result.map.size(), "");
    std::printf("%-44s %12.4f %12s\n", "map: median distance to surface (m)", Median(absolute), "");
    std::printf("%-44s %12.3f %12s\n", "map: median distance, % of range", Median(relative), "< 1");
  }
  const double slam_s = result.total_s;
  std::printf("%-44s %12.3f %12s\n", "global bundle adjustment CPU (s)", result.global_ba_cpu_s, "");
  std::printf("%-44s %12.2f %12s\n", "frames per second, end to end", args.frames / slam_s, ">= 5");
  std::printf("%-44s %12.2f %12s\n", "frames per CPU second (all threads)", args.frames / cpu_s, "");
  std::printf("%-44s %12.3f %12s\n", "global bundle adjustment (s)", result.global_ba_s, "< 1");
  if (result.global_bundle_adjustment) {
    const auto& ba = *result.global_bundle_adjustment;
    std::printf(
        "  global BA: %d poses, %d points, %d residuals, %d iterations, rms %.3f -> %.3f px, "
        "%d observations pruned, %s, %s\n",
        ba.num_free_poses, ba.num_points, ba.num_residuals, ba.solver.num_iterations,
        ba.initial_rms_px, ba.final_rms_px, ba.num_observations_pruned, ba.linear_solver.c_str(),
        ba.solver.termination.c_str());
  }
  const slam::StageTimes& t = result.stage_totals;
  const slam::StageTimes& c = result.cpu_stage_totals;
  const struct {
    const char* name;
    double wall_s, cpu_s;
  } stages[] = {{!args.video.empty() ? "load (video decode)"
                 : args.decode       ? "load (PNG decode)"
                                     : "load",
                 t.load_s, c.load_s},
                {"detect (mask + SIFT)", t.detect_s, c.detect_s},
                {"stereo match + triangulate", t.stereo_s, c.stereo_s},
                {"temporal match", t.match_s, c.match_s},
                {"motion (E + scale + pose)", t.motion_s, c.motion_s},
                {"map update", t.map_s, c.map_s},
                {"local BA", t.local_ba_s, c.local_ba_s},
                {"place recognition + loops", t.loop_s, c.loop_s},
                {"global BA", result.global_ba_s, result.global_ba_cpu_s}};
  std::printf("\n%-30s %10s %8s %10s %8s\n", "stage", "wall (s)", "share", "CPU (s)", "share");
  for (const auto& stage : stages) {
    std::printf("%-30s %10.3f %7.1f%% %10.3f %7.1f%%\n", stage.name, stage.wall_s,
                100 * stage.wall_s / result.total_s, stage.cpu_s,
                100 * stage.cpu_s / result.total_cpu_s);
  }
  std::printf("%-30s %10.3f %8s %10.3f\n", "total", result.total_s, "", result.total_cpu_s);
  if (FILE* f = std::fopen("/proc/loadavg", "r")) {
    double load1 = 0;
    if (std::fscanf(f, "%lf", &load1) == 1) std::printf("load average (1 min) at the end: %.2f\n", load1);
    std::fclose(f);
  }
  std::printf("CPU per frame %.3f s; on 2 idle cores that is at best %.1f frames/s\n",
              result.total_cpu_s / args.frames, 2.0 * args.frames / result.total_cpu_s);
  if (args.dense_map) {
    const dense::DenseMapOptions defaults;
    const std::vector<double> factors = args.grid_step_factors.empty()
                                            ? std::vector<double>{defaults.grid_step_factor}
                                            : args.grid_step_factors;
    const std::vector<double> spacings = args.keyframe_spacings_m.empty()
                                             ? std::vector<double>{defaults.keyframe_spacing_m}
                                             : args.keyframe_spacings_m;
    for (double factor : factors) {
      for (double spacing : spacings) {
        dense::DenseMapOptions options;
        options.grid_step_factor = factor;
        options.keyframe_spacing_m = spacing;
        DenseMapRun(args, sequence, load, result, cpu_s, options);
      }
    }
  }
  if (args.calibration_runs) CalibrationRuns(args, sequence, load);
  if (!args.video.empty()) std::filesystem::remove_all(video_files.cam0.parent_path());
  return 0;
}

}  // namespace
}  // namespace omnirig

int main(int argc, char** argv) {
  omnirig::ConfigureAllocator();  // as the omnirig service runs
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--loop") == 0) return omnirig::RunLoopBench(argc, argv);
  }
  return omnirig::Run(omnirig::ParseArgs(argc, argv));
}
