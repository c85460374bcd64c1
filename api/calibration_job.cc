#include "api/calibration_job.h"

#include <algorithm>
#include <set>

#include "api/board_json.h"
#include "api/camera_json.h"
#include "api/job_types.h"
#include "api/json_fields.h"
#include "api/recording_input.h"
#include "engine/calib/coverage.h"
#include "engine/calib/model_io.h"
#include "engine/util/check.h"

namespace omnirig::api {
namespace {

using nlohmann::json;

// The options' plain tunables by their JSON keys; "fix", "free", "principal_point_px" and
// "rim_circle_px" are read apart.
OptionTable OptionTableOf(ImageCalibrationOptions* o) {
  CalibrationOptions& c = o->calibrate;
  return {{"huber_loss_px", &c.huber_loss_px},
          {"outlier_sigmas", &c.outlier_sigmas},
          {"min_outlier_px", &c.min_outlier_px},
          {"max_rejection_rounds", &c.max_rejection_rounds},
          {"max_view_rms_px", &c.max_view_rms_px},
          {"min_corners_per_view", &c.min_corners_per_view},
          {"min_views", &c.min_views},
          {"max_num_iterations", &c.max_num_iterations},
          {"refine_subpixel", &o->detect.refine_subpixel},
          {"try_enhanced", &o->detect.try_enhanced},
          {"allow_exhaustive", &o->detect.allow_exhaustive},
          {"redetect", &o->redetect_with_model},
          {"max_views", &o->selection.max_views},
          {"overlay_error_scale", &o->overlay_error_scale}};
}

ImageCalibrationOptions OptionsFromJson(const json& options) {
  ImageCalibrationOptions out;
  const OptionTable table = OptionTableOf(&out);
  std::set<std::string> known = KeysOf(table);
  known.insert({"fix", "free", "principal_point_px", "rim_circle_px"});
  CheckKnownFields(options, "options", known);
  CalibrationOptions& c = out.calibrate;
  if (options.contains("fix")) SetFixedFromJson(options["fix"], "options.fix", true, &c);
  if (options.contains("free")) SetFixedFromJson(options["free"], "options.free", false, &c);
  ReadOptions(options, "options", table);
  if (options.contains("principal_point_px")) {
    c.principal_point_px =
        NumberVector<2>(options["principal_point_px"], "options.principal_point_px");
  }
  if (options.contains("rim_circle_px")) {
    c.rim_circle_px = NumberVector<3>(options["rim_circle_px"], "options.rim_circle_px");
  }
  return out;
}

void HintsFromJson(const json& hints, ImageCalibrationOptions* options) {
  OMNIRIG_CHECK(hints.is_object(), "field 'hints' must be an object of image name -> 4 corners");
  for (const auto& [name, corners] : hints.items()) {
    const std::string path = "hints." + name;
    OMNIRIG_CHECK(corners.is_array() && corners.size() == 4,
                  "field '" << path << "' must be an array of 4 [u, v] pixels");
    std::array<Eigen::Vector2d, 4> hint;
    for (int i = 0; i < 4; ++i) {
      hint[i] = NumberVector<2>(corners[i], path + "[" + std::to_string(i) + "]");
    }
    options->hints[name] = hint;
  }
}

// "svp": {"mirror": {"rim_radius_mm", "rim_height_mm"}, "image", "search_margin_px",
// "num_profiles", "inlier_px"} (all optional; {} finds the rim without a prediction).
SvpOptions SvpFromJson(const json& svp) {
  CheckKnownFields(svp, "svp",
                   {"mirror", "image", "search_margin_px", "num_profiles", "inlier_px"});
  SvpOptions out;
  if (svp.contains("mirror")) {
    const json& mirror = svp["mirror"];
    CheckKnownFields(mirror, "svp.mirror", {"rim_radius_mm", "rim_height_mm"});
    MirrorRim rim;
    rim.rim_radius_m = NumberField(mirror, "svp.mirror", "rim_radius_mm") * 1e-3;
    rim.rim_height_m = NumberField(mirror, "svp.mirror", "rim_height_mm") * 1e-3;
    out.mirror = rim;
  }
  if (svp.contains("image")) out.image = StringField(svp, "svp", "image");
  ReadNumber(svp, "svp", "search_margin_px", &out.check.search_margin_px);
  ReadInteger(svp, "svp", "num_profiles", &out.check.num_profiles);
  ReadNumber(svp, "svp", "inlier_px", &out.check.inlier_px);
  WithErrorPrefix("field 'svp': ", [&] { out.Check(); });
  return out;
}

json CircleToJson(const std::optional<Eigen::Vector3d>& circle) {
  return circle ? json({circle->x(), circle->y(), circle->z()}) : json(nullptr);
}

json SvpToJson(const CalibrationReport& report) {
  const SvpCheckReport& svp = *report.svp;
  return {
      {"image", report.svp_image},
      {"found", svp.found_circle_px.has_value()},
      {"reason", svp.reason},
      {"predicted_circle_px", CircleToJson(svp.predicted_circle_px)},
      {"found_circle_px", CircleToJson(svp.found_circle_px)},
      {"centre_offset_px", svp.predicted_circle_px ? json(svp.centre_offset_px) : json(nullptr)},
      {"radius_offset_px", svp.predicted_circle_px ? json(svp.radius_offset_px) : json(nullptr)},
      {"principal_point_px", {svp.principal_point_px.x(), svp.principal_point_px.y()}},
      {"principal_point_offset_px", svp.principal_point_offset_px},
      {"num_edge_points", svp.num_edge_points},
      {"overlay", kSvpOverlayFileName},
      {"circle_format", "[u, v, radius] in pixels"}};
}

json ImageToJson(const CalibrationImageReport& image) {
  const int inliers = static_cast<int>(std::count(image.inlier.begin(), image.inlier.end(), true));
  json corners = json::array();
  for (const auto& c : image.corners_px) corners.push_back({c.x(), c.y()});
  json out = {{"name", image.name},
              {"used", image.used},
              {"reason", image.reason},
              {"rms_px", image.rms_px},
              {"num_corners", image.corners_px.size()},
              {"num_inliers", inliers},
              {"detector", image.detector},
              {"overlay", OverlayFileName(image.name)},
              {"corners_px", corners},
              {"corner_ids", image.corner_ids}};
  out["cam_from_board"] = image.used ? PoseToJson(image.cam_from_board) : json(nullptr);
  return out;
}

// "frames": what became of every image or frame, in input order: {"name", "used", "reason"},
// with "duplicate_of" for a near duplicate and "detail" where there is more to say.
json FramesToJson(const std::vector<FrameReport>& frames) {
  json out = json::array();
  for (const FrameReport& frame : frames) {
    json entry = {{"name", frame.name}, {"used", frame.used}, {"reason", frame.reason}};
    if (!frame.duplicate_of.empty()) entry["duplicate_of"] = frame.duplicate_of;
    if (!frame.detail.empty()) entry["detail"] = frame.detail;
    out.push_back(std::move(entry));
  }
  return out;
}

// "frame_selection": the cap on a long input's views (null: short enough for every view) and
// the frames per reason.
json FrameSelectionToJson(const CalibrationReport& report) {
  json counts = json::object();
  for (const FrameReport& frame : report.frames) {
    counts[frame.reason] = counts.value(frame.reason, 0) + 1;
  }
  return {{"max_views", report.max_views > 0 ? json(report.max_views) : json(nullptr)},
          {"num_frames", report.frames.size()},
          {"reasons", counts}};
}

}  // namespace

CalibrationRequest CalibrationRequestFromJson(const json& params) {
  // A recording's topic ("recording", "topic"; api/recording_input.h), checked at submission.
  std::set<std::string> known = {"board", "options", "hints", "svp", "camera"};
  const std::set<std::string> recording = RecordingFieldNames();
  known.insert(recording.begin(), recording.end());
  CheckKnownFields(params, "params", known);
  CalibrationRequest request;
  ReadBoardParam(params, &request.board, &request.kalibr_target_file);
  if (params.contains("camera")) {
    const json& camera = params["camera"];
    OMNIRIG_CHECK(camera == "cam0" || camera == "cam1",
                  "field 'params.camera' must be \"cam0\" or \"cam1\" (the folder of the "
                  "camera's images)");
    request.camera = camera.get<std::string>();
  }
  if (params.contains("options")) request.options = OptionsFromJson(params["options"]);
  if (params.contains("hints")) HintsFromJson(params["hints"], &request.options);
  if (params.contains("svp")) request.options.svp = SvpFromJson(params["svp"]);
  WithErrorPrefix("field 'options': ", [&] { request.options.Check(); });
  return request;
}

std::vector<std::string> CalibrationImageNames(const std::optional<std::string>& camera,
                                               const std::vector<std::string>& image_names) {
  std::vector<std::string> names, folder[2];
  for (const std::string& name : image_names) {
    if (IsSideFile(name)) continue;
    names.push_back(name);
    for (int c = 0; c < 2; ++c) {
      if (name.rfind("cam" + std::to_string(c) + "/", 0) == 0) folder[c].push_back(name);
    }
  }
  if (camera) {
    const std::vector<std::string>& chosen = folder[*camera == "cam1" ? 1 : 0];
    OMNIRIG_CHECK(!chosen.empty(), "'camera' is \"" << *camera << "\" but the dataset has no "
                                                     << *camera << "/ images");
    return chosen;
  }
  OMNIRIG_CHECK(folder[0].empty() || folder[1].empty(),
                "the dataset holds images of two cameras (" << folder[0].size() << " in cam0/, "
                    << folder[1].size()
                    << " in cam1/), which one calibration would take for one camera: name the "
                       "camera with \"camera\": \"cam0\" or \"cam1\" in the params");
  return names;
}

json CalibrationReportToJson(const CalibrationReport& report) {
  json camera = CameraToJson(report.camera);
  camera["intrinsics_std"] = IntrinsicsToJson(report.intrinsics_std);
  json images = json::array();
  for (const auto& image : report.images) images.push_back(ImageToJson(image));
  const CalibrationSolverSummary& s = report.solver;
  json result = {
      {"camera", camera},
      {"rms_px", report.rms_px},
      {"mean_px", report.mean_px},
      {"std_px", report.std_px},
      {"rms_all_px", report.rms_all_px},
      {"error_definitions",
       "over the inlier corners of the used views, e = reprojected - detected (px): rms_px = "
       "sqrt(mean |e|^2); mean_px and std_px are the mean and standard deviation of |e|; "
       "rms_all_px includes the rejected outlier corners"},
      {"num_views_used", report.num_views_used},
      {"images", images},
      {"solver",
       {{"num_rounds", s.num_rounds},
        {"iterations", s.num_iterations},
        {"initial_cost", s.initial_cost},
        {"final_cost", s.final_cost},
        {"termination", s.termination},
        {"num_residuals", s.num_residuals},
        {"num_parameters", s.num_parameters},
        {"num_rejected_corners", s.num_rejected_corners},
        {"num_rejected_views", s.num_rejected_views},
        {"brief", s.brief}}},
      {"timings_s",
       {{"detect", report.timings.detect_s},
        {"redetect", report.timings.redetect_s},
        {"init", report.timings.init_s},
        {"solve", report.timings.solve_s},
        {"covariance", report.timings.covariance_s},
        {"calibrate_total", report.timings.total_s}}}};
  if (report.svp) result["svp"] = SvpToJson(report);
  result["frames"] = FramesToJson(report.frames);
  result["frame_selection"] = FrameSelectionToJson(report);
  return result;
}

json WriteCameraExports(const CameraModel& camera, const std::filesystem::path& dir,
                        const std::string& rostopic) {
  std::vector<std::string> warnings;
  WriteTextFile(dir / kCameraOpenCvFileName, ToOpenCvOmnidir(camera, &warnings));
  std::vector<std::string> kalibr_warnings;
  WriteTextFile(dir / kCameraKalibrFileName,
                ToKalibrOmniRadtan(camera, &kalibr_warnings, "cam0", rostopic));
  for (const std::string& warning : kalibr_warnings) {
    if (std::find(warnings.begin(), warnings.end(), warning) == warnings.end()) {
      warnings.push_back("kalibr: " + warning);
    }
  }
  return {{"opencv_omnidir", kCameraOpenCvFileName},
          {"kalibr", kCameraKalibrFileName},
          {"warnings", warnings}};
}

json RegionsToJson(const std::vector<CoverageReport::Region>& regions) {
  json out = json::array();
  for (const CoverageReport::Region& region : regions) {
    out.push_back({{"ring", region.ring},
                   {"from_hour", region.from_hour},
                   {"to_hour", region.to_hour},
                   {"covered_fraction", region.covered_fraction},
                   {"median_uncertainty_px", region.median_uncertainty_px}});
  }
  return out;
}

json WriteCoverageReport(const CalibrationReport& report, const BoardSpec& board,
                         const ImageReader& read, const std::filesystem::path& dir) {
  const CoverageOptions options;
  const CoverageReport coverage = AnalyseCoverageOfImages(report, board, read, options);
  WriteCoverageImages(coverage, dir / kCoverageImageFileName, dir / kUncertaintyImageFileName);
  const bool rim = report.svp && report.svp->found_circle_px;
  json result = {{"image", kCoverageImageFileName},
                 {"disk_centre_px", {coverage.disk_centre_px.x(), coverage.disk_centre_px.y()}},
                 {"disk_radius_px", coverage.disk_radius_px},
                 {"disk_from", rim ? "svp_rim" : "principal_point_inscribed_circle"},
                 {"near_px", options.near_px},
                 {"covered_fraction", coverage.covered_fraction},
                 {"uncertainty_image", nullptr},
                 {"max_uncertainty_px", nullptr},
                 {"median_uncertainty_px", nullptr},
                 {"advice", coverage.advice},
                 {"uncovered_regions", RegionsToJson(coverage.uncovered_regions)},
                 {"uncertain_regions", RegionsToJson(coverage.uncertain_regions)},
                 {"uncertainty_flat", coverage.uncertainty_flat},
                 {"missing_poses", coverage.missing_poses},
                 {"board_poses",
                  {{"max_tilt_deg", coverage.max_tilt_deg},
                   {"min_distance_m", coverage.min_board_distance_m},
                   {"median_distance_m", coverage.median_board_distance_m},
                   {"max_distance_m", coverage.max_board_distance_m}}}};
  if (coverage.uncertainty_valid) {
    result["uncertainty_image"] = kUncertaintyImageFileName;
    result["max_uncertainty_px"] = coverage.max_uncertainty_px;
    result["median_uncertainty_px"] = coverage.median_uncertainty_px;
  }
  return result;
}

json WriteRigExports(const StereoRig& rig, const std::filesystem::path& dir,
                     const std::array<std::string, 2>& rostopics) {
  std::vector<std::string> warnings;
  WriteTextFile(dir / kCamchainKalibrFileName, ToKalibrCamchain(rig, &warnings, rostopics));
  return {{"kalibr_camchain", kCamchainKalibrFileName}, {"warnings", warnings}};
}

namespace {

// The params' recording and topic, when they name one. "camera" picks a folder of the dataset's
// images and "recording" a topic of a recording: both at once is refused rather than guessed.
std::optional<RecordingInput> CalibrationRecording(const json& params,
                                                   const CalibrationRequest& request) {
  std::optional<RecordingInput> recording = RecordingInputFromJson(params, 1);
  OMNIRIG_CHECK(!recording || !request.camera,
                "\"camera\" picks a folder of the dataset's images and \"recording\" a topic of "
                "a recording: give one of them (with \"recording\", \"topic\" names the camera)");
  return recording;
}

}  // namespace

JobType CalibrationJobType() {
  JobType type;
  type.name = "calibration";
  type.validate = [](const json& params) { CalibrationRequestFromJson(params); };
  type.check_inputs = [](const json& params, const SubmissionInputs& inputs) {
    const CalibrationRequest request = CalibrationRequestFromJson(params);
    CheckKalibrTargetFileIn(request.kalibr_target_file, inputs.file_names());
    if (const auto recording = CalibrationRecording(params, request)) {
      CheckRecordingInput(*recording, inputs);
      return;
    }
    CalibrationImageNames(request.camera, inputs.file_names());
  };
  type.run = [](const json& params, const JobContext& context) {
    CalibrationRequest request = CalibrationRequestFromJson(params);
    request.options.calibrate.num_threads = std::max(1, context.num_threads);
    if (!request.kalibr_target_file.empty()) {
      request.board = ReadKalibrTargetFile(context.dataset_dir, request.kalibr_target_file);
    }
    const auto recording = CalibrationRecording(params, request);
    std::optional<RecordingFramesRead> frames;
    ImageReader read = FolderImageReader(context.dataset_dir);
    std::vector<std::string> names;
    if (recording) {
      frames = ReadRecordingFrames(*recording, context.open_recording,
                                   SubRange(context.progress, 0.0, 0.0));
      RecordingImages images = CollectRecordingImages(*frames, context.progress);
      read = std::move(images.read);
      names = std::move(images.names);
    } else {
      names = CalibrationImageNames(request.camera, context.image_names);
    }
    const CalibrationReport report = CalibrateImages(read, names, request.board, request.options,
                                                     context.output_dir, context.progress);
    context.Log("calibration: RMS " + std::to_string(report.rms_px) + " px over " +
                std::to_string(report.num_views_used) + " views; " + report.solver.brief);
    json result = CalibrationReportToJson(report);
    result["exports"] = WriteCameraExports(report.camera, context.output_dir,
                                           recording ? recording->topics[0] : std::string());
    result["coverage"] = WriteCoverageReport(report, request.board, read, context.output_dir);
    if (recording) result["input"] = RecordingFramesJson(*recording, frames->frames);
    return result;
  };
  return type;
}

}  // namespace omnirig::api
