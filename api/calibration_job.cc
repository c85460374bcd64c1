#include "api/calibration_job.h"

#include <algorithm>
#include <set>

#include <opencv2/imgcodecs.hpp>

#include "api/camera_json.h"
#include "api/json_fields.h"
#include "api/job_types.h"
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

}  // namespace

BoardSpec BoardFromJson(const json& board) {
  CheckKnownFields(
      board, "board",
      {"type", "cols", "rows", "square_size_mm", "marker_size_mm", "aruco_dictionary"});
  BoardSpec spec;
  const auto type = board.find("type");
  if (type != board.end()) {
    OMNIRIG_CHECK(type->is_string() && (*type == "checkerboard" || *type == "charuco"),
                  "field 'board.type' must be \"checkerboard\" or \"charuco\"");
    spec.type = *type == "charuco" ? BoardSpec::Type::kCharuco : BoardSpec::Type::kCheckerboard;
  }
  spec.cols = IntegerField(board, "board", "cols");
  spec.rows = IntegerField(board, "board", "rows");
  spec.square_size_m = NumberField(board, "board", "square_size_mm") * 1e-3;
  const bool charuco = spec.type == BoardSpec::Type::kCharuco;
  const bool has_marker = charuco || board.contains("marker_size_mm");
  spec.marker_size_m = has_marker ? NumberField(board, "board", "marker_size_mm") * 1e-3 : 0.0;
  ReadInteger(board, "board", "aruco_dictionary", &spec.aruco_dictionary);
  WithErrorPrefix("field 'board': ", [&] { spec.Check(); });
  return spec;
}

CalibrationRequest CalibrationRequestFromJson(const json& params) {
  CheckKnownFields(params, "params", {"board", "options", "hints", "svp"});
  CalibrationRequest request;
  request.board = BoardFromJson(Field(params, "params", "board"));
  if (params.contains("options")) request.options = OptionsFromJson(params["options"]);
  if (params.contains("hints")) HintsFromJson(params["hints"], &request.options);
  if (params.contains("svp")) request.options.svp = SvpFromJson(params["svp"]);
  WithErrorPrefix("field 'options': ", [&] { request.options.Check(); });
  return request;
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
  return result;
}

json WriteCameraExports(const CameraModel& camera, const std::filesystem::path& dir) {
  std::vector<std::string> warnings;
  WriteTextFile(dir / kCameraOpenCvFileName, ToOpenCvOmnidir(camera, &warnings));
  std::vector<std::string> kalibr_warnings;
  WriteTextFile(dir / kCameraKalibrFileName, ToKalibrOmniRadtan(camera, &kalibr_warnings));
  for (const std::string& warning : kalibr_warnings) {
    if (std::find(warnings.begin(), warnings.end(), warning) == warnings.end()) {
      warnings.push_back("kalibr: " + warning);
    }
  }
  return {{"opencv_omnidir", kCameraOpenCvFileName},
          {"kalibr", kCameraKalibrFileName},
          {"warnings", warnings}};
}

json WriteCoverageReport(const CalibrationReport& report, const BoardSpec& board,
                         const std::filesystem::path& dataset_dir,
                         const std::filesystem::path& dir) {
  cv::Mat background;
  for (const CalibrationImageReport& image : report.images) {
    if (!image.used) continue;
    background = cv::imread((dataset_dir / image.name).string(), cv::IMREAD_COLOR);
    break;
  }
  const Eigen::Vector3d* rim =
      report.svp && report.svp->found_circle_px ? &*report.svp->found_circle_px : nullptr;
  const CoverageOptions options;
  const CoverageReport coverage = AnalyseCoverage(report, board, background, rim, options);
  std::filesystem::create_directories(dir);
  cv::imwrite((dir / kCoverageImageFileName).string(), coverage.coverage_image);
  json result = {{"image", kCoverageImageFileName},
                 {"disk_centre_px", {coverage.disk_centre_px.x(), coverage.disk_centre_px.y()}},
                 {"disk_radius_px", coverage.disk_radius_px},
                 {"disk_from", rim ? "svp_rim" : "principal_point_inscribed_circle"},
                 {"near_px", options.near_px},
                 {"covered_fraction", coverage.covered_fraction},
                 {"uncertainty_image", nullptr},
                 {"max_uncertainty_px", nullptr},
                 {"median_uncertainty_px", nullptr},
                 {"advice", coverage.advice}};
  if (coverage.uncertainty_valid) {
    cv::imwrite((dir / kUncertaintyImageFileName).string(), coverage.uncertainty_image);
    result["uncertainty_image"] = kUncertaintyImageFileName;
    result["max_uncertainty_px"] = coverage.max_uncertainty_px;
    result["median_uncertainty_px"] = coverage.median_uncertainty_px;
  }
  return result;
}

json WriteRigExports(const StereoRig& rig, const std::filesystem::path& dir) {
  std::vector<std::string> warnings;
  WriteTextFile(dir / kCamchainKalibrFileName, ToKalibrCamchain(rig, &warnings));
  return {{"kalibr_camchain", kCamchainKalibrFileName}, {"warnings", warnings}};
}

void RegisterCalibrationJobType() {
  JobType type;
  type.name = "calibration";
  type.validate = [](const json& params) { CalibrationRequestFromJson(params); };
  type.run = [](const json& params, const JobContext& context) {
    CalibrationRequest request = CalibrationRequestFromJson(params);
    request.options.calibrate.num_threads = std::max(1, context.num_threads);
    const CalibrationReport report =
        CalibrateImages(context.dataset_dir, context.image_names, request.board, request.options,
                        context.output_dir, context.progress);
    context.Log("calibration: RMS " + std::to_string(report.rms_px) + " px over " +
                std::to_string(report.num_views_used) + " views; " + report.solver.brief);
    json result = CalibrationReportToJson(report);
    result["exports"] = WriteCameraExports(report.camera, context.output_dir);
    result["coverage"] =
        WriteCoverageReport(report, request.board, context.dataset_dir, context.output_dir);
    return result;
  };
  RegisterJobType(std::move(type));
}

}  // namespace omnirig::api
