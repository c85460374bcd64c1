#include "api/slam_job.h"

#include <algorithm>
#include <cctype>
#include <ctime>
#include <memory>
#include <set>
#include <sstream>

#include "api/camera_json.h"
#include "api/json_fields.h"
#include "api/recording_input.h"
#include "api/stereo_job.h"
#include "engine/calib/calibrate.h"
#include "engine/geometry/ply.h"
#include "engine/slam/evaluation.h"
#include "engine/slam/image_source.h"
#include "engine/slam/map_io.h"
#include "engine/util/check.h"
#include "engine/util/error_prefix.h"
#include "engine/util/image_pairs.h"
#include "engine/util/timer.h"

namespace omnirig::api {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

json BundleAdjustmentToJson(const slam::BundleAdjustmentReport& r) {
  return {{"num_free_poses", r.num_free_poses},     {"num_constant_poses", r.num_constant_poses},
          {"num_points", r.num_points},             {"num_residuals", r.num_residuals},
          {"iterations", r.solver.num_iterations},    {"initial_rms_px", r.initial_rms_px},
          {"final_rms_px", r.final_rms_px},         {"num_observations_pruned", r.num_observations_pruned},
          {"num_points_pruned", r.num_points_pruned}, {"linear_solver", r.linear_solver},
          {"termination", r.solver.termination},      {"time_s", r.solver.time_s}};
}

json CalibrationRefinementToJson(const slam::CalibrationRefinementReport& r,
                                 const slam::BundleAdjustmentReport* global) {
  json change = json::object();
  const CameraModel* before[2] = {&r.before.cam0, &r.before.cam1};
  const CameraModel* after[2] = {&r.after.cam0, &r.after.cam1};
  for (int c = 0; c < 2; ++c) {
    json delta = json::object();
    for (int i = 0; i < UnifiedIntrinsics::kNumParams; ++i) {
      const double d = after[c]->intrinsics.params[i] - before[c]->intrinsics.params[i];
      if (d != 0.0) delta[UnifiedIntrinsics::kNames[i]] = d;
    }
    change["cam" + std::to_string(c)] = delta;
  }
  change["cam0_from_cam1_rotation_deg"] =
      RotationDistanceRad(r.before.cam0_from_cam1.rotation, r.after.cam0_from_cam1.rotation) *
      180.0 / M_PI;
  return {{"refine", slam::CalibrationRefinementName(r.refine)},
          {"applied", r.applied},
          {"reason", r.reason},
          {"free_parameters", r.free_parameters},
          {"num_frames", r.num_frames},
          {"num_observations", {r.num_observations[0], r.num_observations[1]}},
          {"reprojection_rms_px",
           global ? json{{"initial", global->initial_rms_px}, {"final", global->final_rms_px}}
                  : json(nullptr)},
          {"before", RigToJson(r.before)},
          {"after", RigToJson(r.after)},
          {"change", change}};
}

json TimesToJson(const slam::StageTimes& t) {
  return {{"load", t.load_s},   {"detect", t.detect_s}, {"stereo", t.stereo_s},
          {"match", t.match_s}, {"motion", t.motion_s}, {"map", t.map_s},
          {"local_ba", t.local_ba_s}, {"loop", t.loop_s}};
}

// What trajectory.json and the report both say of a frame.
json FrameStateToJson(const slam::FrameReport& f) {
  return {{"name", f.name},
          {"state", f.state},
          {"linked", f.linked},
          {"keyframe", f.keyframe},
          {"in_map", f.in_map},
          {"reason", f.reason},
          {"world_from_rig", f.world_from_rig ? PoseToJson(*f.world_from_rig) : json(nullptr)}};
}

json FrameToJson(const slam::FrameReport& f) {
  json out = FrameStateToJson(f);
  out.update({{"motion_source", f.motion_source},
              {"num_features", {f.num_features[0], f.num_features[1]}},
              {"num_stereo_points", f.num_stereo_points},
              {"num_matches", f.num_matches},
              {"num_essential_inliers", f.num_essential_inliers},
              {"num_scale_inliers", f.num_scale_inliers},
              {"num_tracked_landmarks", f.num_tracked_landmarks},
              {"num_new_landmarks", f.num_new_landmarks},
              {"times_s", TimesToJson(f.times)},
              {"local_bundle_adjustment", f.local_bundle_adjustment
                                              ? BundleAdjustmentToJson(*f.local_bundle_adjustment)
                                              : json(nullptr)}});
  return out;
}

json EvaluationToJson(const slam::TrajectoryErrors& e) {
  json segments = json::array();
  for (const slam::SegmentErrors& segment : e.segments) {
    segments.push_back({{"length_m", segment.length_m},
                        {"num_segments", segment.num_segments},
                        {"translation_rmse_m", segment.translation_rmse_m},
                        {"translation_mean_percent", segment.translation_mean_percent},
                        {"rotation_rmse_deg", segment.rotation_rmse_deg}});
  }
  return {{"num_poses", e.num_poses},
          {"path_length_m", e.path_length_m},
          {"ate_rmse_m", e.ate_rmse_m},
          {"ate_max_m", e.ate_max_m},
          {"rpe_translation_rmse_m", e.rpe_translation_rmse_m},
          {"rpe_rotation_rmse_deg", e.rpe_rotation_rmse_deg},
          {"final_drift_percent", e.final_drift_percent},
          {"max_drift_percent", e.max_drift_percent},
          {"gt_from_estimate", PoseToJson(e.gt_from_estimate)},
          {"rpe_segments", segments},
          {"per_frame",
           {{"distance_m", e.distance_m},
            {"translation_error_m", e.translation_error_m},
            {"rotation_error_deg", e.rotation_error_deg}}}};
}

// Timestamps for the TUM file: the ground truth's when given, else NAME's (NameAsTimestamp),
// else the frame index in seconds.
std::vector<double> Timestamps(const std::vector<ImagePairNames>& pairs,
                               const std::vector<slam::StampedPose>& ground_truth) {
  std::vector<double> stamps(pairs.size());
  for (size_t i = 0; i < pairs.size(); ++i) {
    if (!ground_truth.empty()) {
      stamps[i] = ground_truth[i].timestamp_s;
      continue;
    }
    stamps[i] = NameAsTimestamp(pairs[i].name).value_or(static_cast<double>(i));
  }
  return stamps;
}

json WriteArtifacts(const StereoRig& rig, const slam::SlamResult& result,
                    const std::vector<double>& stamps, const SavedMapSource& map_source,
                    const fs::path& output_dir) {
  fs::create_directories(output_dir);
  json frames = json::array();
  std::vector<slam::StampedPose> tum;
  for (size_t i = 0; i < result.frames.size(); ++i) {
    const slam::FrameReport& f = result.frames[i];
    frames.push_back(FrameStateToJson(f));
    frames.back()["timestamp_s"] = stamps[i];
    if (f.world_from_rig) tum.push_back({stamps[i], *f.world_from_rig});
  }
  const json trajectory = {
      {"world_frame", map_source.map_job
                          ? "the world of the saved map of slam job " + *map_source.map_job
                          : std::string("the rig frame (cam0's frame) of the first tracked frame")},
      {"frames", frames},
      {"rig", RigToJson(rig)}};
  WriteTextFile(output_dir / "trajectory.json", trajectory.dump(2) + "\n");
  slam::WriteTum(output_dir / "trajectory.tum", tum);
  slam::WriteKitti(output_dir / "trajectory.kitti.txt", tum);
  slam::WritePly(output_dir / "map.ply", result.map);
  slam::WriteSavedMap(output_dir / kSavedMapArtifact, result.saved_map);
  return {{"trajectory_json", "trajectory.json"},
          {"trajectory_tum", "trajectory.tum"},
          {"trajectory_kitti", "trajectory.kitti.txt"},
          {"map_ply", "map.ply"},
          {"slam_map", kSavedMapArtifact},
          {"report_json", "report.json"}};
}

std::vector<slam::StampedPose> ReadGroundTruth(const fs::path& path) {
  OMNIRIG_CHECK(fs::is_regular_file(path),
                "ground truth " << path.filename().string() << " is not in the dataset");
  return slam::ReadTum(path);
}

}  // namespace

slam::CalibrationRefinement CalibrationRefinementFromJson(const json& value) {
  using slam::CalibrationRefinement;
  if (value.is_boolean()) {
    return value.get<bool>() ? CalibrationRefinement::kAll : CalibrationRefinement::kNone;
  }
  for (CalibrationRefinement r : {CalibrationRefinement::kNone, CalibrationRefinement::kIntrinsics,
                                  CalibrationRefinement::kRig, CalibrationRefinement::kAll}) {
    if (value == slam::CalibrationRefinementName(r)) return r;
  }
  throw InvalidArgument(
      "field 'options.refine_calibration' must be one of \"none\", "
      "\"intrinsics\", \"rig\", \"all\" (or true/false), not " +
      value.dump());
}

slam::SlamOptions SlamOptionsFromJson(const json& object) {
  slam::SlamOptions o;
  // The plain tunables; seed, refine_calibration and fixed_intrinsics are read below.
  const OptionTable table = {
      {"max_features", &o.features.max_features},
      {"contrast_threshold", &o.features.contrast_threshold},
      {"detection_scale", &o.features.detection_scale},
      {"max_epipolar_error_rad", &o.stereo.max_epipolar_error_rad},
      {"temporal_max_descriptor_ratio", &o.temporal_max_descriptor_ratio},
      {"temporal_gate_rad", &o.temporal_gate_rad},
      {"essential_max_angular_error_rad", &o.essential.max_angular_error_rad},
      {"local_window_frames", &o.local_window_frames},
      {"local_max_iterations", &o.local_max_iterations},
      {"global_bundle_adjustment", &o.global_bundle_adjustment},
      {"huber_scale_px", &o.bundle_adjustment.huber_scale_px},
      {"max_reprojection_error_px", &o.bundle_adjustment.max_reprojection_error_px},
      {"min_features", &o.min_features},
      {"min_stereo_points", &o.min_stereo_points},
      {"min_matches", &o.min_matches},
      {"min_tracked_landmarks", &o.min_tracked_landmarks}};
  std::set<std::string> known = KeysOf(table);
  known.insert({"seed", "refine_calibration", "fixed_intrinsics"});
  CheckKnownFields(object, "options", known);
  ReadOptions(object, "options", table);
  auto has = [&](const char* key) { return object.contains(key); };
  if (has("refine_calibration")) {
    o.calibration_refinement.refine = CalibrationRefinementFromJson(object["refine_calibration"]);
  }
  if (has("fixed_intrinsics")) {
    o.calibration_refinement.fixed_intrinsics =
        FixedIntrinsicsFromJson(object["fixed_intrinsics"], "options.fixed_intrinsics");
  }
  if (has("seed")) {
    OMNIRIG_CHECK(object["seed"].is_number_unsigned() || object["seed"].is_number_integer(),
                  "field 'options.seed' must be a non-negative integer");
    OMNIRIG_CHECK(object["seed"].get<long long>() >= 0, "field 'options.seed' must not be negative");
    o.essential.seed = object["seed"].get<std::uint64_t>();
    o.scale.seed = o.essential.seed;
  }
  WithErrorPrefix("invalid 'options': ", [&] { o.Check(); });
  return o;
}

namespace {

dense::DenseMapOptions DenseMapOptionsFromJson(const json& object) {
  dense::DenseMapOptions options;
  const OptionTable table = {{"voxel_m", &options.voxel_m},
                             {"keyframe_spacing_m", &options.keyframe_spacing_m},
                             {"grid_step_factor", &options.grid_step_factor},
                             {"occupancy_cell_m", &options.occupancy_cell_m},
                             {"obstacle_min_height_m", &options.obstacle_min_height_m},
                             {"obstacle_max_height_m", &options.obstacle_max_height_m}};
  CheckKnownFields(object, "params.dense_map", KeysOf(table));
  ReadOptions(object, "params.dense_map", table);
  if (!object.contains("occupancy_cell_m")) {
    options.occupancy_cell_m = std::max(options.occupancy_cell_m, options.voxel_m);
  }
  options.Check();
  return options;
}

// Fuses the dense clouds of keyframes (tracked frames at least keyframe_spacing_m apart) along
// the estimated trajectory and writes dense_map.ply and the occupancy grid.
json FuseDenseMap(const StereoRig& rig, const slam::SlamResult& result,
                  const std::function<slam::StereoImages(int)>& load,
                  const dense::DenseMapOptions& options, int num_threads,
                  const fs::path& output_dir, const ProgressSink& progress) {
  const Timer timer;
  dense::DenseMap map(options);
  std::vector<std::optional<Rigid3d>> world_from_rig;
  for (const slam::FrameReport& frame : result.frames) {
    world_from_rig.push_back(frame.world_from_rig);
  }
  // SLAM has reported 1.0; the fusion's stage is named, its fraction stays there.
  const ProgressSink fusion_progress = SubRange(progress, 1.0, 1.0);
  const dense::KeyframeFusionReport fusion = dense::FuseKeyframes(
      rig, world_from_rig,
      [&](int i) {
        slam::StereoImages images = load(i);
        return std::array<cv::Mat, 2>{images.cam0, images.cam1};
      },
      num_threads, fusion_progress, &map);
  json keyframes = json::array();
  for (int i : fusion.keyframes) keyframes.push_back(result.frames[i].name);
  const PlyCloud cloud = map.Cloud();
  WritePly(output_dir / "dense_map.ply", cloud);
  const dense::OccupancyGrid grid = map.Occupancy();
  dense::WriteOccupancyGrid(output_dir / "occupancy.pgm", output_dir / "occupancy.yaml", grid);
  return {{"keyframes", keyframes},
          {"num_points", cloud.size()},
          {"voxel_m", options.voxel_m},
          {"keyframe_spacing_m", options.keyframe_spacing_m},
          {"grid_step_factor", options.grid_step_factor},
          {"stereo_seconds", fusion.stereo_s},
          {"floor_height_m", grid.floor_height_m},
          {"occupancy_size", {grid.cells.cols, grid.cells.rows}},
          {"seconds", timer.ElapsedSeconds()}};
}

}  // namespace

SlamParams SlamParamsFromJson(const json& params) {
  SlamParams parsed;
  // "frame_step", "start_s", "end_s", "pair_tolerance_s" (each optional).
  const OptionTable frames = {{"frame_step", &parsed.frames.frame_step},
                              {"start_s", &parsed.frames.start_s},
                              {"end_s", &parsed.frames.end_s},
                              {"pair_tolerance_s", &parsed.frames.pair_tolerance_s}};
  std::set<std::string> known = KeysOf(frames);
  // "live" and "live_idle_timeout_s" are the live job's (api/live_slam.h): a live job whose
  // server stopped runs again as a batch job over the frames it stored.
  known.insert({"rig", "ground_truth", "options", "dense_map", "live", "live_idle_timeout_s", "map"});
  // A recording's topics ("recording", "topics"; api/recording_input.h), checked at submission.
  const std::set<std::string> recording = RecordingFieldNames();
  known.insert(recording.begin(), recording.end());
  CheckKnownFields(params, "params", known);
  parsed.rig_job = RigJobField(params);
  if (params.contains("map")) {
    const std::string map = StringField(params, "params", "map");
    OMNIRIG_CHECK(!map.empty(), "field 'params.map' must be the id of a succeeded slam job");
    parsed.map_job = map;
  }
  if (params.contains("ground_truth")) {
    const std::string name = StringField(params, "params", "ground_truth");
    OMNIRIG_CHECK(!name.empty() && name.find("..") == std::string::npos && name.front() != '/',
                  "field 'params.ground_truth' must name a file inside the dataset");
    parsed.ground_truth = name;
  }
  if (params.contains("options")) parsed.options = SlamOptionsFromJson(params["options"]);
  if (params.contains("dense_map")) parsed.dense_map = DenseMapOptionsFromJson(params["dense_map"]);
  ReadOptions(params, "params", frames);
  WithErrorPrefix("invalid 'params': ", [&] { parsed.frames.Check(); });
  parsed.video_only_fields =
      params.contains("start_s") || params.contains("end_s") || params.contains("pair_tolerance_s");
  return parsed;
}

namespace {

std::string Lower(std::string text) {
  for (char& c : text) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return text;
}

// Names the service stores as videos (as storage/video_container.h's IsVideoName).
bool IsVideoFileName(const std::string& name) {
  const std::string ext = Lower(fs::path(name).extension().string());
  return ext == ".mp4" || ext == ".m4v" || ext == ".mov" || ext == ".mkv" || ext == ".webm" ||
         ext == ".avi";
}

// CPU seconds of the whole process (the decoder may run threads of its own).
double ProcessCpuSeconds() {
  timespec now{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &now);
  return static_cast<double>(now.tv_sec) + 1e-9 * static_cast<double>(now.tv_nsec);
}

// Checks that each camera's frames have the size the rig was calibrated for.
void CheckVideoSizes(const StereoRig& rig, const slam::StereoVideoFiles& files,
                     const slam::StereoVideoInfo& info) {
  const CameraModel* camera[2] = {&rig.cam0, &rig.cam1};
  for (int c = 0; c < 2; ++c) {
    if (info.width[c] == camera[c]->width && info.height[c] == camera[c]->height) continue;
    const std::string what =
        files.stacked() ? files.cam0.filename().string() + "'s " + (c == 0 ? "top" : "bottom") +
                              " half (cam" + std::to_string(c) + ")"
                        : (c == 0 ? files.cam0 : files.cam1).filename().string() + "'s frames";
    throw InvalidArgument(
        what + " are " + std::to_string(info.width[c]) + "x" + std::to_string(info.height[c]) +
        " but the rig's cam" + std::to_string(c) + " is calibrated for " +
        std::to_string(camera[c]->width) + "x" + std::to_string(camera[c]->height));
  }
}

// What RunSlam reads: the frames' names, their timestamps (for trajectory.tum), the ground truth
// per frame (or none) and the loader.
struct SlamInput {
  std::vector<std::string> names;
  std::vector<double> timestamps_s;
  std::vector<slam::StampedPose> ground_truth;
  slam::StereoFrameLoader load;
  nlohmann::json source;  // the result's "input": what was read, and how
};

// The ground truth's pose nearest each frame's timestamp, within `tolerance_s`.
std::vector<slam::StampedPose> MatchGroundTruth(const fs::path& path,
                                                const std::vector<double>& stamps,
                                                double tolerance_s) {
  std::vector<slam::StampedPose> poses = ReadGroundTruth(path);
  std::sort(poses.begin(), poses.end(),
            [](const auto& a, const auto& b) { return a.timestamp_s < b.timestamp_s; });
  OMNIRIG_CHECK(!poses.empty(), "ground truth " << path.filename().string() << " holds no pose");
  std::vector<slam::StampedPose> matched;
  for (const double t : stamps) {
    auto it = std::lower_bound(poses.begin(), poses.end(), t,
                               [](const auto& pose, double v) { return pose.timestamp_s < v; });
    if (it == poses.end() ||
        (it != poses.begin() && t - (it - 1)->timestamp_s < it->timestamp_s - t)) {
      --it;
    }
    OMNIRIG_CHECK(std::abs(it->timestamp_s - t) <= tolerance_s,
                  "ground truth " << path.filename().string() << " has no pose within "
                                  << tolerance_s * 1000 << " ms of the frame at " << t << " s");
    matched.push_back({t, it->world_from_rig});
  }
  return matched;
}

SlamInput PrepareVideoInput(const StereoRig& rig, const slam::StereoVideoFiles& files,
                            const slam::VideoFrameOptions& frame_options,
                            const std::optional<fs::path>& ground_truth,
                            const ProgressSink& progress) {
  const slam::StereoVideoInfo info = slam::ProbeStereoVideo(files);
  CheckVideoSizes(rig, files, info);
  // The timestamp pass reads the whole recording once; SLAM's own fractions follow it.
  const ProgressSink pass = SubRange(progress, 0.0, 0.0);
  const double pass_start_s = ProcessCpuSeconds();
  const Timer pass_timer;
  std::vector<slam::StereoVideoFrame> frames =
      slam::PairStereoVideoFrames(files, frame_options, pass);
  const double tolerance_s = frame_options.pair_tolerance_s > 0 ? frame_options.pair_tolerance_s
                                                                : 0.25 / info.video[0].fps;
  SlamInput input;
  json file_names = {files.cam0.filename().string()};
  if (!files.stacked()) file_names.push_back(files.cam1.filename().string());
  input.source = {
      {"kind", files.stacked() ? "stacked_video" : "video_pair"},
      {"files", file_names},
      {"codec", info.video[0].codec},
      {"fps", info.video[0].fps},
      {"frame_count", info.video[0].frame_count},
      {"frame_size", {info.width[0], info.height[0]}},
      {"pair_tolerance_s", tolerance_s},
      {"frame_step", frame_options.frame_step},
      {"num_frames", frames.size()},
      // The pass that reads and pairs every timestamp before the first frame (decoding only).
      {"timestamp_pass_s", pass_timer.ElapsedSeconds()},
      {"timestamp_pass_cpu_s", ProcessCpuSeconds() - pass_start_s}};
  for (const auto& frame : frames) {
    input.names.push_back(frame.name);
    input.timestamps_s.push_back(frame.timestamp_s);
  }
  if (ground_truth) {
    input.ground_truth = MatchGroundTruth(*ground_truth, input.timestamps_s, tolerance_s);
  }
  auto reader = std::make_shared<slam::StereoVideoReader>(files, std::move(frames));
  input.load = [reader](int i) { return reader->Load(i); };
  return input;
}

SlamInput PrepareImageInput(const fs::path& dataset_dir,
                            const std::vector<std::string>& image_names, int frame_step,
                            const std::optional<fs::path>& ground_truth) {
  const std::vector<ImagePairNames> all = MatchImagePairs(image_names);
  std::vector<slam::StampedPose> gt;
  if (ground_truth) {
    gt = ReadGroundTruth(*ground_truth);
    OMNIRIG_CHECK(gt.size() == all.size(),
                  "ground truth " << ground_truth->filename().string() << " has " << gt.size()
                                  << " poses but the sequence has " << all.size()
                                  << " stereo frames (one pose per frame, in order)");
  }
  const std::vector<double> all_stamps = Timestamps(all, gt);
  std::vector<ImagePairNames> pairs;
  SlamInput input;
  for (size_t i = 0; i < all.size(); i += frame_step) {
    pairs.push_back(all[i]);
    input.names.push_back(all[i].name);
    input.timestamps_s.push_back(all_stamps[i]);
    if (!gt.empty()) input.ground_truth.push_back(gt[i]);
  }
  input.source = {{"kind", "images"},
                  {"frame_step", frame_step},
                  {"num_frames", input.names.size()},
                  {"num_image_pairs", all.size()}};
  input.load = slam::StereoImageLoader(dataset_dir, std::move(pairs));
  return input;
}

// The frames of a recording's two topics, paired by header stamp, decoded as SLAM reads them.
SlamInput PrepareRecordingInput(const StereoRig& rig, const RecordingInput& recording,
                                const OpenRecording& open,
                                const std::optional<fs::path>& ground_truth,
                                const ProgressSink& progress) {
  const double pass_start_s = ProcessCpuSeconds();
  const Timer pass_timer;
  RecordingFramesRead read = ReadRecordingFrames(recording, open, SubRange(progress, 0.0, 0.0));
  SlamInput input;
  input.source = RecordingFramesJson(recording, read.frames);
  // The pass that reads every message's header stamp before the first frame (no pixels).
  input.source["timestamp_pass_s"] = pass_timer.ElapsedSeconds();
  input.source["timestamp_pass_cpu_s"] = ProcessCpuSeconds() - pass_start_s;
  for (const io::RecordingFrame& frame : read.frames.frames) {
    input.names.push_back(frame.name);
    input.timestamps_s.push_back(frame.timestamp_s);
  }
  if (ground_truth) {
    // Poses are matched to frames as a recording's stereo frames are to each other.
    const double tolerance_s = read.frames.pair_tolerance_s;
    input.ground_truth = MatchGroundTruth(*ground_truth, input.timestamps_s, tolerance_s);
  }
  auto reader = std::make_shared<io::RecordingFrameReader>(read.source, std::move(read.frames));
  const CameraModel cameras[2] = {rig.cam0, rig.cam1};
  input.load = [reader, cameras, recording](int k) {
    std::vector<cv::Mat> images = reader->Load(k);
    for (int c = 0; c < 2; ++c) {
      const cv::Mat& image = images[c];
      OMNIRIG_CHECK(image.cols == cameras[c].width && image.rows == cameras[c].height,
                    recording.topics[c] << "'s frames are " << image.cols << "x" << image.rows
                                        << " but the rig's cam" << c << " is calibrated for "
                                        << cameras[c].width << "x" << cameras[c].height);
    }
    return slam::StereoImages{images[0], images[1]};
  };
  return input;
}

// Runs SLAM over prepared frames and writes its artifacts.
json RunSlamOnInput(const StereoRig& rig, const SlamInput& input,
                    const slam::SlamOptions& options, const fs::path& output_dir,
                    const ProgressSink& progress,
                    const std::function<void(const std::string&)>& log,
                    const std::optional<dense::DenseMapOptions>& dense_map,
                    const SavedMapSource& map_source) {
  const ProgressSink frame_progress{
      [&](double fraction, const std::string& stage, const std::string& message) {
        progress.Report(fraction, stage, message);
        if (log && !message.empty()) log(message);
      },
      progress.is_cancelled};
  const slam::SlamResult result =
      slam::RunSlam(rig, input.names, input.load, options, frame_progress);
  return WriteSlamReport(rig, result, input.timestamps_s, input.ground_truth, input.source,
                         input.load, dense_map, options.num_threads, output_dir, progress,
                         map_source);
}

// The report's figures of a SLAM run: counts, timings, bundle adjustment, frames and loops.
json SlamResultToJson(const slam::SlamResult& result) {
  json report;
  report["num_frames"] = result.frames.size();
  report["num_tracked"] = result.num_tracked;
  report["num_lost"] = result.num_lost;
  report["num_map_points"] = result.map.size();
  report["frames_per_second"] = result.total_s > 0 ? result.frames.size() / result.total_s : 0.0;
  report["timings_s"] = TimesToJson(result.stage_totals);
  report["timings_s"].update({{"global_ba", result.global_ba_s}, {"total", result.total_s}});
  // CPU seconds of the threads that ran each stage: the stable measure on a shared machine.
  report["cpu_timings_s"] = TimesToJson(result.cpu_stage_totals);
  report["cpu_timings_s"].update(
      {{"global_ba", result.global_ba_cpu_s}, {"total", result.total_cpu_s}});
  report["global_bundle_adjustment"] = result.global_bundle_adjustment
                                           ? BundleAdjustmentToJson(*result.global_bundle_adjustment)
                                           : json(nullptr);
  report["calibration_refinement"] =
      result.calibration_refinement
          ? CalibrationRefinementToJson(*result.calibration_refinement,
                                        result.global_bundle_adjustment
                                            ? &*result.global_bundle_adjustment
                                            : nullptr)
          : json(nullptr);
  json frames = json::array();
  for (const slam::FrameReport& f : result.frames) frames.push_back(FrameToJson(f));
  report["frames"] = frames;
  report["num_keyframes"] = result.num_keyframes;
  json loops = json::array();
  for (const slam::LoopReport& loop : result.loops) {
    loops.push_back({{"frame", loop.frame},
                     {"frame_index", loop.frame_index},
                     {"matched_frame", loop.matched_frame},
                     {"matched_frame_index", loop.matched_frame_index},
                     {"inliers", loop.inliers},
                     {"correction_m", loop.correction_m},
                     {"correction_deg", loop.correction_deg},
                     {"pose_graph", loop.pose_graph}});
  }
  report["loops"] = loops;
  return report;
}

// The tracked frames' trajectory against the ground truth (`gt`, one pose per frame); null with
// fewer than two tracked frames.
json EvaluateTracked(const slam::SlamResult& result, const std::vector<slam::StampedPose>& gt) {
  std::vector<Rigid3d> estimate, truth;
  for (size_t i = 0; i < result.frames.size(); ++i) {
    if (!result.frames[i].world_from_rig) continue;
    estimate.push_back(*result.frames[i].world_from_rig);
    truth.push_back(gt[i].world_from_rig);
  }
  return estimate.size() >= 2 ? EvaluationToJson(slam::EvaluateTrajectory(estimate, truth))
                              : json(nullptr);
}

}  // namespace

std::optional<slam::StereoVideoFiles> FindStereoVideos(const fs::path& dataset_dir,
                                                       const std::vector<std::string>& names) {
  std::vector<std::string> found[3];  // cam0, cam1, stacked
  bool has_pair_images = false;
  for (const std::string& name : names) {
    if (name.rfind("cam0/", 0) == 0 || name.rfind("cam1/", 0) == 0) has_pair_images = true;
    if (name.find('/') != std::string::npos || !IsVideoFileName(name)) continue;
    const std::string stem = Lower(fs::path(name).stem().string());
    const int slot = stem == "cam0" ? 0 : stem == "cam1" ? 1 : stem == "stacked" ? 2 : -1;
    if (slot >= 0) found[slot].push_back(name);
  }
  if (found[0].empty() && found[1].empty() && found[2].empty()) return std::nullopt;
  const char* kinds[3] = {"cam0", "cam1", "stacked"};
  for (int k = 0; k < 3; ++k) {
    OMNIRIG_CHECK(found[k].size() <= 1, "the dataset holds " << found[k].size() << " " << kinds[k]
                                                             << " videos (" << found[k][0] << ", "
                                                             << found[k][1] << "): keep one");
  }
  const bool pair = !found[0].empty() || !found[1].empty();
  OMNIRIG_CHECK(
      !(pair && !found[2].empty()),
      "the dataset holds both a video pair and a stacked video (" << found[2][0] << "): keep one");
  OMNIRIG_CHECK(!has_pair_images,
                "the dataset holds both videos and cam0/ cam1/ images: a slam job reads one "
                "recording; put the other in its own dataset");
  if (!pair) return slam::StereoVideoFiles{dataset_dir / found[2][0], ""};
  for (int c = 0; c < 2; ++c) {
    OMNIRIG_CHECK(!found[c].empty(), found[1 - c][0] << " has no partner: a video pair is cam0.EXT "
                                                        "and cam1.EXT");
  }
  return slam::StereoVideoFiles{dataset_dir / found[0][0], dataset_dir / found[1][0]};
}

namespace {

// The ground truth the params name must be a file of the dataset; the error lists the TUM files
// the dataset has, so that a mistyped name is put right at once.
void CheckGroundTruthPresent(const std::string& name, const SubmissionInputs& dataset) {
  if (fs::is_regular_file(dataset.dataset_dir / name)) return;
  std::vector<std::string> tum_files;
  std::error_code error;
  for (fs::recursive_directory_iterator it(dataset.dataset_dir, error), end; !error && it != end;
       it.increment(error)) {
    if (it->is_regular_file(error) && it->path().extension() == ".tum") {
      tum_files.push_back(fs::relative(it->path(), dataset.dataset_dir).generic_string());
    }
  }
  std::sort(tum_files.begin(), tum_files.end());
  std::ostringstream os;
  os << "ground truth '" << name << "' is not in dataset " << dataset.dataset_id;
  if (tum_files.empty()) {
    os << ", which holds no .tum file (a TUM trajectory: 'time tx ty tz qx qy qz qw' per line)";
  } else {
    os << "; its .tum files:";
    for (const std::string& file : tum_files) os << " " << file;
  }
  throw InvalidArgument(os.str());
}

void CheckSavedMapFitsRig(const SlamParams& parsed,
                          const std::function<json(const std::string&)>& load_result) {
  const json result = load_result(*parsed.map_job);
  const std::string& id = *parsed.map_job;
  OMNIRIG_CHECK(result.is_object() && result.contains("saved_map") &&
                    result["saved_map"].is_object() &&
                    result["saved_map"].value("rig_job", json()).is_string(),
                "slam job " << id << " in 'map' has no saved map (" << kSavedMapArtifact
                            << "): it ran before slam jobs saved their maps; run it again");
  OMNIRIG_CHECK(result["saved_map"].value("num_keyframes", 0) > 0,
                "the saved map of slam job " << id << " in 'map' holds no keyframe (it tracked "
                                             << "no frame): there is nothing to localise in");
  const std::string map_rig = result["saved_map"]["rig_job"].get<std::string>();
  OMNIRIG_CHECK(map_rig == parsed.rig_job, "the saved map of slam job "
                                               << id << " in 'map' was made with rig " << map_rig
                                               << ", not with this job's rig " << parsed.rig_job
                                               << ": a map is localised in with the rig that "
                                                  "made it");
}

}  // namespace

void CheckSlamMap(const json& params, const std::function<json(const std::string&)>& load_result) {
  const SlamParams parsed = SlamParamsFromJson(params);
  if (parsed.map_job) CheckSavedMapFitsRig(parsed, load_result);
}

void CheckSlamInputs(const json& params, const SubmissionInputs& dataset) {
  const SlamParams parsed = SlamParamsFromJson(params);
  if (parsed.map_job) CheckSavedMapFitsRig(parsed, dataset.load_result);
  if (parsed.ground_truth) CheckGroundTruthPresent(*parsed.ground_truth, dataset);
  if (const auto recording = RecordingInputFromJson(params, 2)) {
    CheckRecordingInput(*recording, dataset);
    return;
  }
  CheckImagesFitRig(params, dataset);
  const auto videos = FindStereoVideos(dataset.dataset_dir, dataset.file_names());
  if (!videos) {
    OMNIRIG_CHECK(!parsed.video_only_fields,
                  "'start_s', 'end_s' and 'pair_tolerance_s' select frames of videos, and dataset "
                      << dataset.dataset_id
                      << " holds none (cam0.EXT and cam1.EXT, or stacked.EXT)");
    // Stereo frames are pairs cam0/NAME + cam1/NAME: refused now rather than at the job's start.
    WithErrorPrefix("a slam job needs stereo frames: ",
                    [&] { return MatchImagePairs(dataset.file_names()); });
    return;
  }
  CheckVideoSizes(LoadRig(dataset.load_result, parsed.rig_job), *videos,
                  slam::ProbeStereoVideo(*videos));
}

json RunSlamOnDataset(const StereoRig& rig, const fs::path& dataset_dir,
                      const std::vector<std::string>& image_names, const slam::SlamOptions& options,
                      const std::optional<fs::path>& ground_truth, const fs::path& output_dir,
                      const ProgressSink& progress,
                      const std::function<void(const std::string&)>& log,
                      const std::optional<dense::DenseMapOptions>& dense_map,
                      const slam::VideoFrameOptions& frame_options,
                      const SavedMapSource& map_source) {
  options.Check();
  frame_options.Check();
  const auto videos = FindStereoVideos(dataset_dir, image_names);
  const SlamInput input =
      videos ? PrepareVideoInput(rig, *videos, frame_options, ground_truth, progress)
             : PrepareImageInput(dataset_dir, image_names, frame_options.frame_step, ground_truth);
  return RunSlamOnInput(rig, input, options, output_dir, progress, log, dense_map, map_source);
}

json WriteSlamReport(const StereoRig& rig, const slam::SlamResult& result,
                     const std::vector<double>& timestamps_s,
                     const std::vector<slam::StampedPose>& ground_truth, const json& input,
                     const slam::StereoFrameLoader& load,
                     const std::optional<dense::DenseMapOptions>& dense_map, int num_threads,
                     const fs::path& output_dir, const ProgressSink& progress,
                     const SavedMapSource& map_source) {
  json report = SlamResultToJson(result);
  report["artifacts"] = WriteArtifacts(rig, result, timestamps_s, map_source, output_dir);
  report["saved_map"] = {
      {"artifact", kSavedMapArtifact},
      {"format_version", slam::kSavedMapVersion},
      {"num_keyframes", result.saved_map.keyframes.size()},
      {"num_landmarks", result.saved_map.landmarks.size()},
      {"rig_job", map_source.rig_job},
      {"localised_in", map_source.map_job ? json(*map_source.map_job) : json(nullptr)}};
  report["localised_in_map_fraction"] =
      map_source.map_job && !result.frames.empty()
          ? json(static_cast<double>(result.num_frames_in_map) / result.frames.size())
          : json(nullptr);
  report["input"] = input;
  if (!ground_truth.empty()) report["evaluation"] = EvaluateTracked(result, ground_truth);
  if (dense_map) {
    report["dense_map"] =
        FuseDenseMap(rig, result, load, *dense_map, num_threads, output_dir, progress);
    report["artifacts"]["dense_map_ply"] = "dense_map.ply";
    report["artifacts"]["occupancy_pgm"] = "occupancy.pgm";
    report["artifacts"]["occupancy_yaml"] = "occupancy.yaml";
  }
  WriteTextFile(output_dir / "report.json", report.dump(2) + "\n");
  return report;
}

json RunSlamJob(const json& params, const JobContext& context) {
  const SlamParams parsed = SlamParamsFromJson(params);
  const StereoRig rig = LoadRig(context.load_result, parsed.rig_job);
  slam::SlamOptions options = parsed.options;
  options.num_threads = std::max(1, context.num_threads);
  if (parsed.map_job) options.saved_map = LoadSavedMap(context, *parsed.map_job);
  std::optional<fs::path> ground_truth;
  if (parsed.ground_truth) ground_truth = context.dataset_dir / *parsed.ground_truth;
  if (const auto recording = RecordingInputFromJson(params, 2)) {
    const SlamInput input = PrepareRecordingInput(rig, *recording, context.open_recording,
                                                  ground_truth, context.progress);
    return RunSlamOnInput(rig, input, options, context.output_dir, context.progress, context.log,
                          parsed.dense_map, {parsed.rig_job, parsed.map_job});
  }
  return RunSlamOnDataset(rig, context.dataset_dir, context.image_names, options, ground_truth,
                          context.output_dir, context.progress, context.log, parsed.dense_map,
                          parsed.frames, {parsed.rig_job, parsed.map_job});
}

std::shared_ptr<const slam::SavedMap> LoadSavedMap(const JobContext& context,
                                                   const std::string& map_job) {
  OMNIRIG_CHECK(context.artifact_path, "this service cannot read other jobs' artifacts");
  const fs::path path = context.artifact_path(map_job, kSavedMapArtifact);
  return WithErrorPrefix("the saved map of slam job " + map_job + " in 'map': ", [&] {
    return std::make_shared<const slam::SavedMap>(slam::ReadSavedMap(path));
  });
}

JobType SlamJobType() {
  JobType type;
  type.name = "slam";
  type.validate = [](const json& params) { SlamParamsFromJson(params); };
  type.referenced_jobs = [](const json& params) {
    const SlamParams parsed = SlamParamsFromJson(params);
    std::vector<JobReference> references = {{parsed.rig_job, "relative_pose", "rig"}};
    if (parsed.map_job) references.push_back({*parsed.map_job, "slam", "map"});
    return references;
  };
  type.check_inputs = CheckSlamInputs;
  type.run = RunSlamJob;
  return type;
}

}  // namespace omnirig::api
