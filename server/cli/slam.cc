// `omnirig slam`: trajectory and metric map from a folder of stereo pairs, the same engine call,
// artifacts and report as the `slam` job type.
//
//   omnirig slam --rig rig.json DIR [--gt traj.tum] -o OUTDIR [--options options.json]
//       [--threads N] [--refine-calibration none|intrinsics|rig|all] [--dense-map VOXEL_M]
//
// rig.json is a relative_pose result (cam0_from_cam1 and both cameras); DIR holds cam0/NAME and
// cam1/NAME. OUTDIR receives trajectory.json, trajectory.tum, map.ply and report.json.
// --refine-calibration sets options.refine_calibration (the global bundle adjustment refines
// the cameras' intrinsics and/or the rig's rotation); the refined calibration is in
// report.json's "calibration_refinement".

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iostream>

#include <nlohmann/json.hpp>

#include "api/camera_json.h"
#include "api/slam_job.h"
#include "engine/util/check.h"
#include "server/cli/args.h"
#include "server/cli/commands.h"
#include "server/cli/files.h"
#include "server/cli/job_options.h"

namespace omnirig::cli {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

void DeclareOptions(ArgParser* args) {
  args->AddOption("rig", "", "relative_pose result JSON (cam0_from_cam1 and both cameras)");
  args->AddOption("gt", "", "ground-truth trajectory (TUM format, one pose per frame) to evaluate");
  args->AddOption("o", "slam_out", "output folder");
  args->AddOption("options", "", "JSON file with the job's \"options\" object");
  args->AddOption("threads", "2", "worker threads");
  AddCacheDirOption(args);
  args->AddOption("dense-map", "",
                  "voxel size in metres: also fuse the keyframes' dense clouds into "
                  "dense_map.ply and write occupancy.pgm/.yaml (ROS map_server)");
  args->AddOption("refine-calibration", "",
                  "none|intrinsics|rig|all: refine the calibration in the global bundle "
                  "adjustment (overrides the options file)");
  args->AddOption("frame-step", "1", "every n-th stereo frame");
  args->AddOption("start-s", "0", "videos: first timestamp to read, seconds");
  args->AddOption("end-s", "", "videos: last timestamp to read, seconds (default: to the end)");
  args->AddOption("pair-tolerance-s", "0",
                  "videos: frames of cam0 and cam1 pair within this (0: a quarter frame period)");
  args->SetPositional("DIR",
                      "folder with cam0/ and cam1/ images, paired and ordered by name, or "
                      "with videos cam0.EXT and cam1.EXT (or stacked.EXT: cam0 on top)");
}

slam::SlamOptions OptionsFromArgs(const ArgParser& args) {
  slam::SlamOptions options;
  if (args.Has("options")) {
    options = api::SlamOptionsFromJson(ReadJsonFile(args.Get("options"), "--options"));
  }
  if (args.Has("refine-calibration")) {
    try {
      options.calibration_refinement.refine =
          api::CalibrationRefinementFromJson(json(args.Get("refine-calibration")));
    } catch (const InvalidArgument&) {
      throw InvalidArgument("--refine-calibration must be none, intrinsics, rig or all, not '" +
                            args.Get("refine-calibration") + "'");
    }
    options.Check();  // e.g. refinement without the global bundle adjustment
  }
  options.num_threads = args.GetInt("threads");
  OMNIRIG_CHECK(options.num_threads >= 1, "--threads must be at least 1");
  return options;
}

std::optional<dense::DenseMapOptions> DenseMapFromArgs(const ArgParser& args) {
  if (!args.Has("dense-map")) return std::nullopt;
  dense::DenseMapOptions dense_map;
  dense_map.voxel_m = args.GetDouble("dense-map");
  dense_map.occupancy_cell_m = std::max(dense_map.occupancy_cell_m, dense_map.voxel_m);
  const fs::path cache_dir = CacheDirFromArgs(args, args.Get("o"));
  if (!cache_dir.empty()) dense_map.rectification_tables_dir = cache_dir / "rectification";
  dense_map.Check();
  return dense_map;
}

slam::VideoFrameOptions FramesFromArgs(const ArgParser& args) {
  slam::VideoFrameOptions frames;
  frames.frame_step = args.GetInt("frame-step");
  frames.start_s = args.GetDouble("start-s");
  if (args.Has("end-s")) frames.end_s = args.GetDouble("end-s");
  frames.pair_tolerance_s = args.GetDouble("pair-tolerance-s");
  frames.Check();
  return frames;
}

void PrintReport(const json& report, const fs::path& out_dir) {
  std::cout << "frames: " << report["num_frames"] << ", tracked: " << report["num_tracked"]
            << ", map points: " << report["num_map_points"]
            << ", frames/s: " << report["frames_per_second"] << "\n";
  if (report.contains("evaluation") && !report["evaluation"].is_null()) {
    const json& e = report["evaluation"];
    std::cout << "ATE RMSE " << e["ate_rmse_m"] << " m, drift " << e["final_drift_percent"]
              << " % of " << e["path_length_m"] << " m\n";
  }
  if (report.contains("calibration_refinement") && !report["calibration_refinement"].is_null()) {
    const json& r = report["calibration_refinement"];
    if (r["applied"].get<bool>()) {
      std::cout << "calibration refined (" << r["refine"].get<std::string>()
                << "): reprojection RMS " << r["reprojection_rms_px"]["initial"] << " -> "
                << r["reprojection_rms_px"]["final"] << " px, changes " << r["change"].dump()
                << "\n";
    } else {
      std::cout << "calibration not refined: " << r["reason"].get<std::string>() << "\n";
    }
  }
  std::cout << "wrote " << (out_dir / "trajectory.json").string() << ", "
            << "trajectory.tum, map.ply, report.json\n";
}

}  // namespace

int RunSlam(const Args& raw_args) {
  ArgParser args("slam",
                 "Trajectory and metric map from a stereo sequence (cam0/NAME, cam1/NAME).");
  DeclareOptions(&args);
  if (!args.Parse(raw_args)) return args.exit_code();
  OMNIRIG_CHECK(args.positional().size() == 1, "expected one DIR (see --help)");
  OMNIRIG_CHECK(args.Has("rig"), "--rig is required (a relative_pose result JSON)");
  const StereoRig rig = api::RigFromJson(ReadJsonFile(args.Get("rig"), "--rig"));
  const slam::SlamOptions options = OptionsFromArgs(args);
  std::optional<fs::path> ground_truth;
  if (args.Has("gt")) ground_truth = fs::path(args.Get("gt"));
  const std::optional<dense::DenseMapOptions> dense_map = DenseMapFromArgs(args);
  const fs::path dir = args.positional()[0];
  const slam::VideoFrameOptions frames = FramesFromArgs(args);
  const json report = api::RunSlamOnDataset(
      rig, dir, fs::is_directory(dir / "cam0") ? ListPairImages(dir) : ListFiles(dir), options,
      ground_truth, args.Get("o"), ProgressSink{PrintProgress, nullptr}, nullptr, dense_map,
      frames);
  PrintReport(report, args.Get("o"));
  return 0;
}

}  // namespace omnirig::cli
