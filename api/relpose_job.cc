#include "api/relpose_job.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <iterator>
#include <set>
#include <string>

#include "api/board_json.h"
#include "api/calibration_job.h"
#include "api/camera_json.h"
#include "api/json_fields.h"
#include "api/recording_input.h"
#include "engine/util/check.h"

namespace omnirig::api {
namespace {

using nlohmann::json;

// A non-negative quantity, or null where it was not measured (-1).
json NullableRms(double rms_px) { return rms_px >= 0.0 ? json(rms_px) : json(nullptr); }

json Vector3Json(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

}  // namespace

RelativePoseParams RelativePoseParamsFromJson(const json& params) {
  // The intrinsics the rig refines are the model's: a request naming them itself is refused
  // with the field that chooses them.
  for (const char* field : {"refine_intrinsics", "fixed_intrinsics"}) {
    OMNIRIG_CHECK(!params.is_object() || !params.contains(field),
                  "field 'params." << field
                                   << "' is not a parameter: the intrinsics the joint fit "
                                      "refines are chosen by 'params.intrinsics_model' (auto, "
                                      "fixed, tangential_fixed, tangential_free_cam0, "
                                      "tangential_free_cam1 or free; default auto)");
  }
  std::set<std::string> known = {"board",         "calibrations",       "intrinsics_model",
                                 "resolve_corner_order", "huber_loss_px", "max_num_iterations",
                                 "sync_false_alarm_rate"};
  // A recording's topics ("recording", "topics"; api/recording_input.h), checked at submission.
  const std::set<std::string> recording = RecordingFieldNames();
  known.insert(recording.begin(), recording.end());
  CheckKnownFields(params, "params", known);
  RelativePoseParams out;
  ReadBoardParam(params, &out.board, &out.kalibr_target_file);
  if (params.contains("calibrations") && params["calibrations"].is_string()) {
    out.kalibr_camchain_file = DatasetYamlName(params["calibrations"], "params.calibrations",
                                               "a Kalibr camchain");
  } else if (params.contains("calibrations")) {
    const json& calibrations = params["calibrations"];
    CheckKnownFields(calibrations, "calibrations", {"cam0", "cam1"});
    out.cam0_calibration_job = JobIdField(calibrations, "calibrations", "cam0");
    out.cam1_calibration_job = JobIdField(calibrations, "calibrations", "cam1");
  }
  if (params.contains("intrinsics_model")) {
    out.options.intrinsics_model = StringField(params, "params", "intrinsics_model");
    const std::string& model = out.options.intrinsics_model;
    OMNIRIG_CHECK(
        std::find(std::begin(kRigIntrinsicsModelNames), std::end(kRigIntrinsicsModelNames),
                  model) != std::end(kRigIntrinsicsModelNames),
        "field 'params.intrinsics_model' must be auto, fixed, tangential_fixed, "
        "tangential_free_cam0, tangential_free_cam1 or free, got '"
            << model << "'");
    OMNIRIG_CHECK((!out.cam0_calibration_job && out.kalibr_camchain_file.empty()) ||
                      !RigIntrinsicsModelNeedsOwnCalibration(model),
                  "'params.intrinsics_model' " << model
                                               << " needs the job to calibrate the cameras "
                                                  "itself (no 'params.calibrations')");
  }
  RelativePoseOptions& relpose = out.options.relpose;
  ReadBool(params, "params", "resolve_corner_order", &relpose.resolve_corner_order);
  ReadNumber(params, "params", "huber_loss_px", &relpose.huber_loss_px);
  ReadInteger(params, "params", "max_num_iterations", &relpose.max_num_iterations);
  if (params.contains("sync_false_alarm_rate")) {
    const double rate = NumberField(params, "params", "sync_false_alarm_rate");
    OMNIRIG_CHECK(rate >= 0.0 && rate < 1.0,
                  "field 'params.sync_false_alarm_rate' must be in [0, 1), got " << rate);
    relpose.sync_test.false_alarm_rate = rate;
  }
  out.options.Check();
  return out;
}

namespace {

// What the result says of a pair and of a calibration's single-camera view alike.
json ViewToJson(const RelativePosePairReport& pair) {
  return {{"name", pair.name},
          {"used", pair.used},
          {"reason", pair.reason},
          {"rms_px", NullableRms(pair.used ? pair.rms_px : -1.0)},
          {"num_corners", pair.num_corners}};
}

json PairToJson(const RelativePosePairReport& pair) {
  json entry = ViewToJson(pair);
  entry["cam1_corner_order"] = pair.cam1_order;
  if (pair.used) entry["cam0_from_board"] = PoseToJson(pair.cam0_from_board);
  entry["sync_statistic"] = NullableRms(pair.sync_statistic);
  entry["board_offset_m"] = NullableRms(pair.board_offset_m);
  entry["board_rotation_deg"] = NullableRms(pair.board_rotation_deg);
  return entry;
}

}  // namespace

json RelativePoseResultToJson(const RelativePoseReport& report, const json& camera0,
                              const json& camera1, bool intrinsics_refined) {
  json result = RigToJson(report.rig);
  if (!intrinsics_refined) result["cameras"] = {{"cam0", camera0}, {"cam1", camera1}};
  result["baseline_m"] = report.baseline_m;
  result["baseline_std_m"] = report.baseline_std_m;
  // The cluster-robust std over pairs (null when fewer than 3 pairs): see relative_pose.h.
  result["baseline_std_robust_m"] = NullableRms(report.baseline_std_robust_m);
  result["rotation_std_robust_deg"] = NullableRms(report.rotation_std_robust_deg);
  result["translation_std_m"] = Vector3Json(report.translation_std_m);
  result["rotation_std_deg"] = report.rotation_std_deg;
  result["rms_px"] = report.rms_px;
  result["num_pairs_used"] = report.num_pairs_used;
  result["linear_cam0_from_cam1"] = PoseToJson(report.linear_cam0_from_cam1);
  result["averaged_cam0_from_cam1"] = PoseToJson(report.averaged_cam0_from_cam1);
  result["spread_eigen_ratio"] = report.spread_eigen_ratio;
  result["intrinsics_refined"] = intrinsics_refined;
  json pairs = json::array(), single_views = json::array();
  for (const RelativePosePairReport& pair : report.pairs) {
    if (pair.single_camera >= 0) {
      single_views.push_back(ViewToJson(pair));
      single_views.back()["camera"] = "cam" + std::to_string(pair.single_camera);
    } else {
      pairs.push_back(PairToJson(pair));
    }
  }
  const int num_single_views = static_cast<int>(single_views.size());
  result["pairs"] = pairs;
  // Which observations the estimate used: the pairs, and the given calibrations' own views
  // (each in one camera; they join the fit where the intrinsics are refined).
  result["single_camera_views"] = single_views;
  result["observations"] = {
      {"pairs_given", report.pairs.size() - num_single_views},
      {"pairs_used", report.num_pairs_used},
      {"single_camera_views_given", num_single_views},
      {"single_camera_views_used", report.num_single_camera_views_used}};
  const SyncTestReport& sync = report.sync_test;
  result["sync_test"] = {{"run", sync.run},
                         {"corner_noise_px", {sync.corner_noise_px[0], sync.corner_noise_px[1]}},
                         {"dispersion", sync.dispersion},
                         {"median_statistic", sync.median_statistic},
                         {"limit", sync.limit},
                         {"num_pairs_left_out", report.sync_rounds}};
  result["solver"] = {{"initial_cost", report.solver.initial_cost},
                      {"final_cost", report.solver.final_cost},
                      {"num_iterations", report.solver.num_iterations},
                      {"termination", report.solver.termination},
                      {"time_s", report.solver.time_s}};
  return result;
}

namespace {

// A calibration job's camera as the rig starts from it, and what the result says of it.
struct LoadedCalibration {
  GivenCamera camera;
  json camera_json;  // the result's own `camera` (its extra keys such as intrinsics_std kept)
  json provenance;
};

// The used views of a calibration result, as detections.
std::vector<CalibrationView> CalibrationViewsOf(const json& result) {
  std::vector<CalibrationView> views;
  if (!result.contains("images") || !result["images"].is_array()) return views;
  for (const json& image : result["images"]) {
    if (!image.is_object() || !image.value("used", false) || !image.contains("corners_px") ||
        !image.contains("corner_ids")) {
      continue;
    }
    CalibrationView view;
    view.name = image.value("name", "");
    for (const json& corner : image["corners_px"]) {
      view.detection.corners_px.emplace_back(corner.at(0).get<double>(),
                                             corner.at(1).get<double>());
    }
    view.detection.corner_ids = image["corner_ids"].get<std::vector<int>>();
    view.detection.found = view.detection.corners_px.size() == view.detection.corner_ids.size();
    if (view.detection.found) views.push_back(std::move(view));
  }
  return views;
}

LoadedCalibration LoadCalibration(const JobContext& context, const std::string& job_id,
                                  const std::string& camera) {
  OMNIRIG_CHECK(static_cast<bool>(context.load_result),
                "this job cannot read other jobs' results (no calibration loader)");
  const json result = context.load_result(job_id);
  OMNIRIG_CHECK(result.is_object() && result.contains("camera"),
                "calibration job " << job_id << " (" << camera
                                   << ") has no 'camera' in its result; is it a calibration job?");
  LoadedCalibration loaded;
  loaded.camera.model = WithErrorPrefix("calibration job " + job_id + " (" + camera + "): ",
                                        [&] { return CameraFromJson(result["camera"]); });
  loaded.camera.views = CalibrationViewsOf(result);
  loaded.camera_json = result["camera"];
  loaded.provenance = {{"source", "job"}, {"job_id", job_id}};
  if (result.contains("rms_px")) loaded.provenance["rms_px"] = result["rms_px"];
  return loaded;
}

json ModelSelectionToJson(const RigModelSelection& selection) {
  json candidates = json::array();
  for (const RigModelScore& score : selection.candidates) {
    candidates.push_back({{"name", score.name},
                          {"num_free_intrinsics", score.num_free_intrinsics},
                          {"success", score.fit.success},
                          {"baseline_m", score.fit.baseline_m},
                          {"rms_px", score.fit.rms_px},
                          {"num_pairs_used", score.fit.num_pairs_used},
                          {"cv_rms_px", NullableRms(score.cv_rms_px)},
                          {"cv_excess_mse_px2", score.cv_excess_mse_px2},
                          {"cv_excess_se_px2", score.cv_excess_se_px2}});
  }
  return {{"chosen", selection.candidates[selection.chosen].name},
          {"selection", "cross_validation"},
          {"rule", selection.rule},
          {"held_out_pairs", selection.held_out.size()},
          {"candidates", candidates}};
}

}  // namespace

json RunRelativePoseJob(const json& params, const JobContext& context) {
  RelativePoseParams parsed = RelativePoseParamsFromJson(params);
  if (!parsed.kalibr_target_file.empty()) {
    parsed.board = ReadKalibrTargetFile(context.dataset_dir, parsed.kalibr_target_file);
  }
  const StereoPairsInput input = ReadStereoPairs(params, context);
  std::array<std::optional<GivenCamera>, 2> given;
  std::array<json, 2> camera_json, provenance;
  std::optional<Rigid3d> kalibr_cam0_from_cam1;
  if (!parsed.kalibr_camchain_file.empty()) {
    const StereoRig chain =
        ReadKalibrCamchainFile(context.dataset_dir, parsed.kalibr_camchain_file);
    for (int c = 0; c < 2; ++c) {
      given[c] = GivenCamera{c == 0 ? chain.cam0 : chain.cam1, {}};
      camera_json[c] = CameraToJson(given[c]->model);
      provenance[c] = {{"source", "kalibr_camchain"}, {"file", parsed.kalibr_camchain_file}};
    }
    kalibr_cam0_from_cam1 = chain.cam0_from_cam1;
  }
  if (parsed.cam0_calibration_job) {
    const std::string* jobs[2] = {&*parsed.cam0_calibration_job, &*parsed.cam1_calibration_job};
    for (int c = 0; c < 2; ++c) {
      LoadedCalibration loaded = LoadCalibration(context, *jobs[c], "cam" + std::to_string(c));
      given[c] = std::move(loaded.camera);
      camera_json[c] = std::move(loaded.camera_json);
      provenance[c] = std::move(loaded.provenance);
    }
  }
  RigFromImagesOptions options = parsed.options;
  options.relpose.num_threads = std::max(1, context.num_threads);
  const RigFromImagesReport report = EstimateRigFromImages(
      input.read, input.pairs, parsed.board, given, options, context.progress, context.log);
  for (int c = 0; c < 2; ++c) {
    const std::optional<CalibrationReport>& calibration = report.cameras[c].calibration;
    if (!calibration) continue;
    camera_json[c] = CalibrationReportToJson(*calibration)["camera"];
    provenance[c] = {{"source", "calibrated"},
                     {"rms_px", calibration->rms_px},
                     {"num_views_used", calibration->num_views_used}};
  }
  json result = RelativePoseResultToJson(report.fit, camera_json[0], camera_json[1],
                                         report.intrinsics_refined);
  result["calibrations"] = {{"cam0", provenance[0]}, {"cam1", provenance[1]}};
  if (kalibr_cam0_from_cam1) {
    // The camchain's own extrinsic beside this job's estimate, for comparison.
    result["kalibr_camchain"] = {
        {"file", parsed.kalibr_camchain_file},
        {"cam0_from_cam1", PoseToJson(*kalibr_cam0_from_cam1)},
        {"baseline_m", kalibr_cam0_from_cam1->translation.norm()}};
  }
  result["intrinsics_model"] =
      report.selection ? ModelSelectionToJson(*report.selection)
                       : json{{"chosen", report.intrinsics_model}, {"selection", "given"}};
  if (!input.input.is_null()) result["input"] = input.input;
  return result;
}

JobType RelativePoseJobType() {
  JobType type;
  type.name = "relative_pose";
  type.validate = [](const json& params) { RelativePoseParamsFromJson(params); };
  type.referenced_jobs = [](const json& params) {
    const RelativePoseParams parsed = RelativePoseParamsFromJson(params);
    std::vector<JobReference> references;
    if (parsed.cam0_calibration_job) {
      references.push_back({*parsed.cam0_calibration_job, "calibration", "calibrations.cam0"});
    }
    if (parsed.cam1_calibration_job) {
      references.push_back({*parsed.cam1_calibration_job, "calibration", "calibrations.cam1"});
    }
    return references;
  };
  type.check_inputs = [](const json& params, const SubmissionInputs& inputs) {
    const RelativePoseParams parsed = RelativePoseParamsFromJson(params);
    CheckKalibrTargetFileIn(parsed.kalibr_target_file, inputs.file_names());
    CheckDatasetFileIn(parsed.kalibr_camchain_file, "params.calibrations", inputs.file_names());
    if (const auto recording = RecordingInputFromJson(params, 2)) {
      CheckRecordingInput(*recording, inputs);
    }
  };
  type.run = [](const json& params, const JobContext& context) {
    json result = RunRelativePoseJob(params, context);
    std::array<std::string, 2> rostopics;
    if (const auto recording = RecordingInputFromJson(params, 2)) {
      rostopics = {recording->topics[0], recording->topics[1]};
    }
    result["exports"] = WriteRigExports(RigFromJson(result), context.output_dir, rostopics);
    return result;
  };
  return type;
}

}  // namespace omnirig::api
