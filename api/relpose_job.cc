#include "api/relpose_job.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <sstream>

#include <opencv2/imgcodecs.hpp>

#include "api/calibration_job.h"
#include "api/camera_json.h"
#include "api/json_fields.h"
#include "engine/calib/calibrate.h"
#include "engine/calib/detect.h"
#include "engine/util/check.h"

namespace omnirig::api {
namespace {

using nlohmann::json;

// params.intrinsics_model, or its default: "auto" when the intrinsics options were not given,
// "" (those options as given) otherwise.
std::string IntrinsicsModelField(const json& params, bool self_calibrating) {
  const bool explicit_options =
      params.contains("refine_intrinsics") || params.contains("fixed_intrinsics");
  if (!params.contains("intrinsics_model")) return explicit_options ? "" : "auto";
  const std::string model = StringField(params, "params", "intrinsics_model");
  OMNIRIG_CHECK(model == "auto" || model == "fixed" || model == "tangential_fixed" ||
                    model == "tangential_free_cam0" || model == "tangential_free_cam1" ||
                    model == "free",
                "field 'params.intrinsics_model' must be auto, fixed, tangential_fixed, "
                "tangential_free_cam0, tangential_free_cam1 or free, got '"
                    << model << "'");
  OMNIRIG_CHECK(!params.contains("refine_intrinsics"),
                "give 'params.intrinsics_model' or 'params.refine_intrinsics', not both");
  OMNIRIG_CHECK(self_calibrating || model == "auto" || model == "fixed" || model == "free",
                "'params.intrinsics_model' " << model << " needs the job to calibrate the cameras "
                                                         "itself (no 'params.calibrations')");
  return model;
}

// A non-negative quantity, or null where it was not measured (-1).
json NullableRms(double rms_px) { return rms_px >= 0.0 ? json(rms_px) : json(nullptr); }

json Vector3Json(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

}  // namespace

RelativePoseParams RelativePoseParamsFromJson(const json& params) {
  CheckKnownFields(
      params, "params",
      {"board", "calibrations", "refine_intrinsics", "fixed_intrinsics", "intrinsics_model",
       "resolve_corner_order", "huber_loss_px", "max_num_iterations", "sync_false_alarm_rate"});
  RelativePoseParams out;
  out.board = BoardFromJson(Field(params, "params", "board"));
  if (params.contains("calibrations")) {
    const json& calibrations = params["calibrations"];
    CheckKnownFields(calibrations, "calibrations", {"cam0", "cam1"});
    out.cam0_calibration_job = JobIdField(calibrations, "calibrations", "cam0");
    out.cam1_calibration_job = JobIdField(calibrations, "calibrations", "cam1");
  }
  // Without a model: refine the intrinsics with the rig when the job calibrates the cameras
  // itself (a per-camera calibration leaves xi, the focal length and k1 trading off, which
  // scales the board's depth and so the baseline: on bench_relpose's renders +0.17 +- 0.15 %
  // over three seeds against -0.015 +- 0.03 % when refined); keep given calibrations as they
  // are.
  out.options.refine_intrinsics = !out.cam0_calibration_job.has_value();
  ReadBool(params, "params", "refine_intrinsics", &out.options.refine_intrinsics);
  if (params.contains("fixed_intrinsics")) {
    out.options.fixed_intrinsics =
        FixedIntrinsicsFromJson(params["fixed_intrinsics"], "params.fixed_intrinsics");
  }
  out.base_fixed_intrinsics = out.options.fixed_intrinsics;
  out.intrinsics_model = IntrinsicsModelField(params, !out.cam0_calibration_job.has_value());
  if (!out.intrinsics_model.empty() && out.intrinsics_model != "auto") {
    const auto& base = out.base_fixed_intrinsics;
    std::vector<RigIntrinsicsModel> models = StandardRigIntrinsicsModels(base);
    for (const RigIntrinsicsModel& model : PerCameraTangentialModels(base)) models.push_back(model);
    for (const RigIntrinsicsModel& model : models) {
      if (model.name != out.intrinsics_model) continue;
      out.options.refine_intrinsics = model.refine_intrinsics;
      out.options.fixed_intrinsics = model.joint_fixed;
      out.options.cam1_fixed_intrinsics = model.cam1_joint_fixed;
    }
  }
  ReadBool(params, "params", "resolve_corner_order", &out.options.resolve_corner_order);
  ReadNumber(params, "params", "huber_loss_px", &out.options.huber_loss_px);
  ReadInteger(params, "params", "max_num_iterations", &out.options.max_num_iterations);
  if (params.contains("sync_false_alarm_rate")) {
    const double rate = NumberField(params, "params", "sync_false_alarm_rate");
    OMNIRIG_CHECK(rate >= 0.0 && rate < 1.0,
                  "field 'params.sync_false_alarm_rate' must be in [0, 1), got " << rate);
    out.options.sync_test.false_alarm_rate = rate;
  }
  out.options.Check();
  return out;
}

std::vector<ImagePairNames> MatchImagePairs(const std::vector<std::string>& image_names) {
  std::map<std::string, std::string> cam0, cam1;
  for (const std::string& name : image_names) {
    if (name.rfind("cam0/", 0) == 0 && name.size() > 5) cam0[name.substr(5)] = name;
    if (name.rfind("cam1/", 0) == 0 && name.size() > 5) cam1[name.substr(5)] = name;
  }
  OMNIRIG_CHECK(!cam0.empty() && !cam1.empty(),
                "the dataset needs images named cam0/NAME and cam1/NAME (found "
                    << cam0.size() << " cam0/ and " << cam1.size() << " cam1/ images)");
  std::vector<std::string> missing;
  for (const auto& [name, path] : cam0) {
    if (cam1.count(name) == 0) missing.push_back(path + " has no cam1/" + name);
  }
  for (const auto& [name, path] : cam1) {
    if (cam0.count(name) == 0) missing.push_back(path + " has no cam0/" + name);
  }
  if (!missing.empty()) {
    std::ostringstream os;
    os << "images without a partner (pairs are matched by name):";
    for (const std::string& m : missing) os << " " << m << ";";
    throw InvalidArgument(os.str());
  }
  std::vector<ImagePairNames> pairs;
  for (const auto& [name, path] : cam0) pairs.push_back({name, path, cam1[name]});
  return pairs;
}

std::optional<double> NameAsTimestamp(const std::string& name) {
  std::string stem = std::filesystem::path(name).stem().string();
  // A recording's frames are named "t" and the time (slam::FrameName, e.g. "t000012.345").
  if (stem.size() > 1 && stem[0] == 't') stem.erase(0, 1);
  char* end = nullptr;
  const double value = std::strtod(stem.c_str(), &end);
  if (stem.empty() || end != stem.c_str() + stem.size()) return std::nullopt;
  return value;
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

// A camera's model and the JSON the result reports for it.
struct CameraSource {
  CameraModel model;
  json camera_json;
  json provenance;
  // A given calibration's used views (its result's "images"): corners and ids.
  std::vector<CalibrationView> views;
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

CameraSource LoadCalibration(const JobContext& context, const std::string& job_id,
                             const std::string& camera) {
  OMNIRIG_CHECK(static_cast<bool>(context.load_result),
                "this job cannot read other jobs' results (no calibration loader)");
  const json result = context.load_result(job_id);
  OMNIRIG_CHECK(result.is_object() && result.contains("camera"),
                "calibration job " << job_id << " (" << camera
                                   << ") has no 'camera' in its result; is it a calibration job?");
  CameraSource source;
  source.model = WithErrorPrefix("calibration job " + job_id + " (" + camera + "): ",
                                 [&] { return CameraFromJson(result["camera"]); });
  source.camera_json = result["camera"];
  source.views = CalibrationViewsOf(result);
  source.provenance = {{"source", "job"}, {"job_id", job_id}};
  if (result.contains("rms_px")) source.provenance["rms_px"] = result["rms_px"];
  return source;
}

std::vector<cv::Mat> ReadImages(const JobContext& context, const std::vector<std::string>& names,
                                const ProgressSink& progress) {
  std::vector<cv::Mat> images;
  for (size_t i = 0; i < names.size(); ++i) {
    progress.ThrowIfCancelled();
    const std::filesystem::path path = context.dataset_dir / names[i];
    cv::Mat image = cv::imread(path.string(), cv::IMREAD_GRAYSCALE);
    OMNIRIG_CHECK(!image.empty(), "image " << names[i] << " cannot be read (missing, truncated or "
                                                          "not an image)");
    images.push_back(std::move(image));
    progress.Report((i + 1.0) / names.size(), "read", names[i]);
  }
  return images;
}

// Every image of a camera must have its calibration's size (or, without one, a common size).
void CheckImageSizes(const std::vector<cv::Mat>& images, const std::vector<std::string>& names,
                     int width, int height, const std::string& what) {
  std::ostringstream os;
  int num_bad = 0;
  for (size_t i = 0; i < images.size(); ++i) {
    if (images[i].cols == width && images[i].rows == height) continue;
    if (num_bad++ < 5) os << " " << names[i] << " is " << images[i].cols << "x" << images[i].rows << ";";
  }
  OMNIRIG_CHECK(num_bad == 0, num_bad << " image(s) differ from " << what << " (" << width << "x"
                                      << height << "):" << os.str());
}

std::vector<BoardDetection> DetectAll(const std::vector<cv::Mat>& images,
                                      const std::vector<std::string>& names,
                                      const BoardSpec& board, const ProgressSink& progress) {
  std::vector<BoardDetection> detections;
  for (size_t i = 0; i < images.size(); ++i) {
    progress.ThrowIfCancelled();
    detections.push_back(DetectBoard(images[i], board, DetectOptions()));
    progress.Report((i + 1.0) / images.size(), "detect",
                    names[i] + (detections.back().found ? ": found" : ": not found"));
  }
  return detections;
}

// The same intrinsics stay fixed here as in the joint refinement (`fixed`), so that both
// steps fit one model.
CameraSource CalibrateFromOwnImages(const std::vector<std::string>& names,
                                    const std::vector<BoardDetection>& detections, int width,
                                    int height, const BoardSpec& board,
                                    const std::array<bool, UnifiedIntrinsics::kNumParams>& fixed,
                                    const JobContext& context, const ProgressSink& progress) {
  std::vector<CalibrationView> views;
  for (size_t i = 0; i < names.size(); ++i) views.push_back({names[i], detections[i]});
  CalibrationOptions options;
  options.fixed = fixed;
  options.num_threads = std::max(1, context.num_threads);
  const CalibrationReport report = Calibrate(views, width, height, board, options, progress);
  CameraSource source;
  source.model = report.camera;
  source.camera_json = CalibrationReportToJson(report)["camera"];
  source.provenance = {{"source", "calibrated"},
                       {"rms_px", report.rms_px},
                       {"num_views_used", report.num_views_used}};
  return source;
}

// Whether two detections are the same image's (a given calibration that included the pairs'
// own images): the same corners at the same pixels.
bool SameDetection(const BoardDetection& a, const BoardDetection& b) {
  if (a.corners_px.size() != b.corners_px.size() || a.corner_ids != b.corner_ids) return false;
  for (size_t c = 0; c < a.corners_px.size(); ++c) {
    if ((a.corners_px[c] - b.corners_px[c]).norm() > 1e-6) return false;
  }
  return true;
}

// The given calibrations' views, as single-camera views after the pairs (relative_pose.h):
// those that are not one of the pairs' own images. With the intrinsics refined they join the
// joint fit, a camera chain in the manner of Kalibr.
void AddCalibrationViews(const std::array<std::optional<CameraSource>, 2>& cameras,
                         std::vector<StereoBoardPair>* board_pairs) {
  const size_t num_pairs = board_pairs->size();
  for (int c = 0; c < 2; ++c) {
    if (!cameras[c]) continue;
    for (const CalibrationView& view : cameras[c]->views) {
      bool own = false;
      for (size_t i = 0; i < num_pairs && !own; ++i) {
        own = SameDetection(view.detection, c == 0 ? (*board_pairs)[i].cam0 : (*board_pairs)[i].cam1);
      }
      if (own) continue;
      StereoBoardPair single;
      single.name = "cam" + std::to_string(c) + " calibration view " + view.name;
      (c == 0 ? single.cam0 : single.cam1) = view.detection;
      single.single_camera_view = true;
      board_pairs->push_back(std::move(single));
    }
  }
}

void LogBaseline(const RelativePoseReport& report, const JobContext& context) {
  context.Log("baseline " + std::to_string(report.baseline_m * 1e3) + " mm from " +
              std::to_string(report.num_pairs_used) + " pairs, RMS " +
              std::to_string(report.rms_px) + " px");
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

// "intrinsics_model": "auto": the candidate models (AutoRigIntrinsicsModels), each camera from
// its own calibration with the model's fixed set (a camera whose tangential terms the model
// fixes is calibrated again with k3 = k4 = 0, once), scored by cross-validation; the chosen
// one's fit is the result.
json RunAutoModel(const RelativePoseParams& parsed, const RelativePoseOptions& options,
                  const std::array<std::vector<std::string>, 2>& names,
                  const std::array<std::vector<BoardDetection>, 2>& detections,
                  const std::array<std::vector<cv::Mat>, 2>& images,
                  const std::vector<StereoBoardPair>& board_pairs,
                  const std::array<std::optional<CameraSource>, 2>& cameras,
                  const JobContext& context) {
  std::vector<RigModelCandidate> candidates;
  std::vector<std::array<const CameraSource*, 2>> sources;
  std::array<std::optional<CameraSource>, 2> recalibrated;
  const std::array<bool, UnifiedIntrinsics::kNumParams>& base = parsed.base_fixed_intrinsics;
  // Given calibrations are not redone: their own intrinsics kept, or refined with the rig.
  std::vector<RigIntrinsicsModel> models = AutoRigIntrinsicsModels(base);
  if (parsed.cam0_calibration_job) {
    models.erase(std::remove_if(models.begin(), models.end(),
                                [](const RigIntrinsicsModel& model) {
                                  return model.name != "fixed" && model.name != "free";
                                }),
                 models.end());
  }
  for (const RigIntrinsicsModel& model : models) {
    std::array<const CameraSource*, 2> source{};
    for (int c = 0; c < 2; ++c) {
      if (model.CalibrationFixed(c) == base) {
        source[c] = &*cameras[c];
        continue;
      }
      // The only other set the candidates use: base with k3 = k4 = 0.
      if (!recalibrated[c]) {
        context.Log("calibrating cam" + std::to_string(c) + " with k3 = k4 = 0");
        recalibrated[c] = CalibrateFromOwnImages(
            names[c], detections[c], images[c][0].cols, images[c][0].rows, parsed.board,
            model.CalibrationFixed(c), context,
            SubRange(context.progress, 0.7 + 0.025 * c, 0.725 + 0.025 * c));
      }
      source[c] = &*recalibrated[c];
    }
    candidates.push_back({model, source[0]->model, source[1]->model});
    sources.push_back(source);
  }
  const RigModelSelection selection = SelectRigIntrinsicsModel(
      parsed.board, board_pairs, candidates, options, SubRange(context.progress, 0.75, 1.0));
  if (selection.chosen < 0) {
    throw InvalidArgument("no relative pose: " + selection.candidates[0].fit.message);
  }
  const RigModelScore& chosen = selection.candidates[selection.chosen];
  context.Log("intrinsics model: " + selection.rule);
  LogBaseline(chosen.fit, context);
  // The candidates each ended on their own summary: the job ends on the chosen one's.
  context.progress.Report(1.0, "done", RelativePoseSummary(chosen.fit));
  const auto& source = sources[selection.chosen];
  json result = RelativePoseResultToJson(chosen.fit, source[0]->camera_json,
                                         source[1]->camera_json,
                                         candidates[selection.chosen].model.refine_intrinsics);
  result["calibrations"] = {{"cam0", source[0]->provenance}, {"cam1", source[1]->provenance}};
  result["intrinsics_model"] = ModelSelectionToJson(selection);
  return result;
}

// Each camera's images, all of its calibration's size (or of its first image's without one).
std::array<std::vector<cv::Mat>, 2> ReadCheckedImages(
    const std::array<std::vector<std::string>, 2>& names,
    const std::array<std::optional<CameraSource>, 2>& cameras, const JobContext& context) {
  std::array<std::vector<cv::Mat>, 2> images;
  for (int c = 0; c < 2; ++c) {
    images[c] = ReadImages(context, names[c], SubRange(context.progress, 0.05 * c, 0.05 * (c + 1)));
    const int width = cameras[c] ? cameras[c]->model.width : images[c][0].cols;
    const int height = cameras[c] ? cameras[c]->model.height : images[c][0].rows;
    CheckImageSizes(images[c], names[c], width, height,
                    cameras[c] ? "cam" + std::to_string(c) + "'s calibration"
                               : "cam" + std::to_string(c) + "'s first image");
  }
  return images;
}

}  // namespace

json RunRelativePoseJob(const json& params, const JobContext& context) {
  const RelativePoseParams parsed = RelativePoseParamsFromJson(params);
  const std::vector<ImagePairNames> pairs = MatchImagePairs(context.image_names);
  std::array<std::vector<std::string>, 2> names;
  for (const ImagePairNames& pair : pairs) {
    names[0].push_back(pair.cam0);
    names[1].push_back(pair.cam1);
  }
  std::array<std::optional<CameraSource>, 2> cameras;
  if (parsed.cam0_calibration_job) {
    cameras[0] = LoadCalibration(context, *parsed.cam0_calibration_job, "cam0");
    cameras[1] = LoadCalibration(context, *parsed.cam1_calibration_job, "cam1");
  }
  // Everything that can refuse the input does so before detection starts.
  const std::array<std::vector<cv::Mat>, 2> images = ReadCheckedImages(names, cameras, context);
  std::array<std::vector<BoardDetection>, 2> detections;
  for (int c = 0; c < 2; ++c) {
    detections[c] = DetectAll(images[c], names[c], parsed.board,
                              SubRange(context.progress, 0.1 + 0.3 * c, 0.35 + 0.3 * c));
    if (!cameras[c]) {
      context.Log("calibrating cam" + std::to_string(c) + " from its own images");
      // A named model's calibration fixes what its joint refinement does, per camera.
      const auto& fixed = c == 1 && parsed.options.cam1_fixed_intrinsics
                              ? *parsed.options.cam1_fixed_intrinsics
                              : parsed.options.fixed_intrinsics;
      cameras[c] = CalibrateFromOwnImages(names[c], detections[c], images[c][0].cols,
                                          images[c][0].rows, parsed.board, fixed, context,
                                          SubRange(context.progress, 0.35 + 0.3 * c, 0.4 + 0.3 * c));
    }
  }
  std::vector<StereoBoardPair> board_pairs;
  for (size_t i = 0; i < pairs.size(); ++i) {
    board_pairs.push_back({pairs[i].name, detections[0][i], detections[1][i]});
  }
  AddCalibrationViews(cameras, &board_pairs);
  RelativePoseOptions options = parsed.options;
  options.num_threads = std::max(1, context.num_threads);
  if (parsed.intrinsics_model == "auto") {
    return RunAutoModel(parsed, options, names, detections, images, board_pairs, cameras, context);
  }
  const RelativePoseReport report =
      EstimateRelativePose(cameras[0]->model, cameras[1]->model, parsed.board, board_pairs,
                           options, SubRange(context.progress, 0.7, 1.0));
  if (!report.success) throw InvalidArgument("no relative pose: " + report.message);
  LogBaseline(report, context);
  json result = RelativePoseResultToJson(report, cameras[0]->camera_json, cameras[1]->camera_json,
                                         options.refine_intrinsics);
  result["calibrations"] = {{"cam0", cameras[0]->provenance}, {"cam1", cameras[1]->provenance}};
  result["intrinsics_model"] = {
      {"chosen", parsed.intrinsics_model.empty() ? "custom" : parsed.intrinsics_model},
      {"selection", "given"}};
  return result;
}

void RegisterRelativePoseJobType() {
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
  type.run = [](const json& params, const JobContext& context) {
    json result = RunRelativePoseJob(params, context);
    result["exports"] = WriteRigExports(RigFromJson(result), context.output_dir);
    return result;
  };
  RegisterJobType(std::move(type));
}

}  // namespace omnirig::api
