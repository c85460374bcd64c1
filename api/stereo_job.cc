#include "api/stereo_job.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <iomanip>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <sstream>
#include <stdexcept>
#include <utility>
#include <vector>

#include "api/camera_json.h"
#include "api/json_fields.h"
#include "api/recording_input.h"
#include "engine/dense/pipeline.h"
#include "engine/estimators/epipolar.h"
#include "engine/slam/map_io.h"
#include "engine/util/check.h"
#include "engine/util/image_pairs.h"

namespace omnirig::api {
namespace {

using nlohmann::json;

// The tunables of each method by their JSON keys; dark_level and max_relative_range_std belong
// to both.
OptionTable SparseTable(StereoReconstructOptions* o) {
  return {{"max_features", &o->max_features},
          {"ratio_test", &o->ratio_test},
          {"max_epipolar_error_rad", &o->max_epipolar_error_rad},
          {"mutual_check", &o->mutual_check},
          {"min_parallax_rad", &o->min_parallax_rad},
          {"max_reprojection_error_rad", &o->max_reprojection_error_rad},
          {"keypoint_std_px", &o->keypoint_std_px},
          {"max_relative_range_std", &o->max_relative_range_std},
          {"dark_level", &o->dark_level},
          {"mask_margin_px", &o->mask_margin_px}};
}

OptionTable DenseTable(dense::DenseStereoOptions* o) {
  return {{"grid_step_rad", &o->grid.step_rad},
          {"max_parallax_deg", &o->max_parallax_deg},
          {"block_size", &o->block_size},
          {"uniqueness_ratio", &o->uniqueness_ratio},
          {"speckle_window_cells", &o->speckle_window_cells},
          {"speckle_range_cells", &o->speckle_range_cells},
          {"left_right_max_diff_cells", &o->left_right_max_diff_cells},
          {"confidence_window_cells", &o->confidence_window_cells},
          {"image_noise_grey", &o->image_noise_grey},
          {"min_confidence", &o->min_confidence},
          {"disparity_std_cells", &o->disparity_std_cells},
          {"disparity_std_scale", &o->disparity_std_scale},
          {"max_relative_range_std", &o->max_relative_range_std},
          {"dark_level", &o->dark_level},
          {"mask_margin_cells", &o->mask_margin_cells},
          {"max_epipolar_offset_cells", &o->max_epipolar_offset_cells}};
}

// A pair whose confident cells are fewer than this fraction of its mirror cells is reported as
// a bad pair (dark, blurred, out of sync): the room renders give about 0.8, a pair with one
// image shifted by 4 px about 0.3.
constexpr double kFewConfidentFraction = 0.5;

double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

// A pair's "median_range_m" and "median_range_std_m" over its points (either method's).
template <typename Point>
json RangeMediansJson(const std::vector<Point>& points) {
  std::vector<double> ranges, stds;
  ranges.reserve(points.size());
  stds.reserve(points.size());
  for (const Point& p : points) {
    ranges.push_back(p.point_in_cam0.norm());
    stds.push_back(p.range_std_m);
  }
  return {{"median_range_m", Median(ranges)}, {"median_range_std_m", Median(stds)}};
}

json PairJson(const std::string& name, const StereoPairReport& report) {
  json pair = {{"name", name},
               {"num_keypoints", {report.num_keypoints0, report.num_keypoints1}},
               {"num_candidates", report.num_candidates},
               {"num_matches", report.num_matches},
               {"num_points", report.points.size()},
               {"rejected",
                {{"parallax", report.num_rejected_parallax},
                 {"reprojection", report.num_rejected_reprojection},
                 {"uncertain", report.num_rejected_uncertain}}}};
  pair.update(RangeMediansJson(report.points));
  return pair;
}

}  // namespace

StereoReconstructParams StereoReconstructParamsFromJson(const json& params) {
  OMNIRIG_CHECK(params.is_object(), "'params' must be a JSON object");
  StereoReconstructParams out;
  if (params.contains("method")) {
    OMNIRIG_CHECK(params["method"].is_string() &&
                      (params["method"] == "dense" || params["method"] == "sparse"),
                  "field 'params.method' must be \"dense\" or \"sparse\"");
    out.method = params["method"].get<std::string>();
  }
  const std::set<std::string> sparse = KeysOf(SparseTable(&out.options));
  const std::set<std::string> dense = KeysOf(DenseTable(&out.dense));
  const std::set<std::string>& fields = out.method == "dense" ? dense : sparse;
  const std::set<std::string>& other = out.method == "dense" ? sparse : dense;
  for (const auto& [key, value] : params.items()) {
    if (key == "rig" || key == "method" || key == "trajectory" || fields.count(key)) continue;
    if (RecordingFieldNames().count(key)) continue;  // checked at submission
    OMNIRIG_CHECK(other.count(key) == 0, "field 'params." << key << "' applies to method '"
                                                          << (out.method == "dense" ? "sparse" : "dense")
                                                          << "' only (this job's method is '"
                                                          << out.method << "')");
    OMNIRIG_CHECK(false, "unknown field 'params." << key << "'");
  }
  out.rig_job = RigJobField(params);
  if (params.contains("trajectory"))
    out.trajectory_job = JobIdField(params, "params", "trajectory");
  if (out.method == "dense") {
    ReadOptions(params, "params", DenseTable(&out.dense));
    out.dense.Check();
  } else {
    ReadOptions(params, "params", SparseTable(&out.options));
    out.options.Check();
  }
  return out;
}

json StereoReconstructOptionsToJson(const StereoReconstructOptions& options) {
  StereoReconstructOptions copy = options;
  return OptionsToJson(SparseTable(&copy));
}

json DenseStereoOptionsToJson(const dense::DenseStereoOptions& options) {
  dense::DenseStereoOptions copy = options;
  return OptionsToJson(DenseTable(&copy));
}

namespace {

// Each pair's cam0 pose in one world, when a trajectory gives it: a slam job's (frames named as
// the pairs) or the dataset's .tum file (by timestamp when the pairs are named by time, else one
// pose per pair in order, as slam's ground truth).
dense::PairPlacement PlaceBySlamJob(const std::string& job_id,
                                    const std::vector<ImagePairNames>& pairs,
                                    const JobContext& context) {
  const json slam = context.load_result(job_id);
  OMNIRIG_CHECK(slam.contains("frames") && slam["frames"].is_array(),
                "job " << job_id << " holds no trajectory (is it a slam job?)");
  std::map<std::string, std::optional<Rigid3d>> by_name;
  for (const json& frame : slam["frames"]) {
    if (!frame.contains("name") || !frame["name"].is_string()) continue;
    const json& pose = frame.value("world_from_rig", json(nullptr));
    by_name[frame["name"].get<std::string>()] =
        pose.is_null() ? std::nullopt : std::optional<Rigid3d>(PoseFromJson(pose));
  }
  dense::PairPlacement placement{"slam job " + job_id, {}, ""};
  int num_unknown = 0;
  for (const ImagePairNames& pair : pairs) {
    const auto it = by_name.find(pair.name);
    num_unknown += it == by_name.end();
    placement.world_from_cam0.push_back(it == by_name.end() ? std::nullopt : it->second);
  }
  OMNIRIG_CHECK(num_unknown < static_cast<int>(pairs.size()),
                "no pair of this dataset is a frame of slam job "
                    << job_id << " (its frames are named as the pairs, e.g. "
                    << (by_name.empty() ? std::string("none") : by_name.begin()->first) << ")");
  return placement;
}

dense::PairPlacement PlaceByTum(const std::string& file, const std::vector<ImagePairNames>& pairs,
                                const JobContext& context) {
  dense::PairPlacement placement{file, std::vector<std::optional<Rigid3d>>(pairs.size()), ""};
  const std::vector<slam::StampedPose> poses = slam::ReadTum(context.dataset_dir / file);
  int num_by_time = 0;
  for (size_t k = 0; k < pairs.size(); ++k) {
    const std::optional<double> stamp = NameAsTimestamp(pairs[k].name);
    for (const slam::StampedPose& pose : poses) {
      if (stamp && std::abs(pose.timestamp_s - *stamp) < 1e-6 * std::max(1.0, std::abs(*stamp))) {
        placement.world_from_cam0[k] = pose.world_from_rig;
        ++num_by_time;
        break;
      }
    }
  }
  if (num_by_time > 0) return placement;
  if (poses.size() == pairs.size()) {
    for (size_t k = 0; k < pairs.size(); ++k) {
      placement.world_from_cam0[k] = poses[k].world_from_rig;
    }
    return placement;
  }
  placement.warning = file + " has " + std::to_string(poses.size()) + " poses for " +
                      std::to_string(pairs.size()) +
                      " pairs and no timestamp equal to a pair's name: the pairs are not placed";
  return placement;
}

std::optional<dense::PairPlacement> PlacePairs(const StereoReconstructParams& parsed,
                                               const std::vector<ImagePairNames>& pairs,
                                               const JobContext& context) {
  if (parsed.trajectory_job) return PlaceBySlamJob(*parsed.trajectory_job, pairs, context);
  std::vector<std::string> tum;
  for (const std::string& name : context.image_names) {
    if (name.size() > 4 && name.compare(name.size() - 4, 4, ".tum") == 0) tum.push_back(name);
  }
  if (tum.empty()) return std::nullopt;
  if (tum.size() > 1) {
    return dense::PairPlacement{tum[0], std::vector<std::optional<Rigid3d>>(pairs.size()),
                                "the dataset holds " + std::to_string(tum.size()) +
                                    " .tum trajectories: name a slam job in 'trajectory' instead"};
  }
  return PlaceByTum(tum[0], pairs, context);
}

json DensePairJson(const std::string& name, const dense::DensePairResult& r) {
  const double confident_fraction =
      r.num_mirror_cells > 0 ? static_cast<double>(r.num_points) / r.num_mirror_cells : 0.0;
  json pair = {{"name", name},
               {"num_mirror_cells", r.num_mirror_cells},
               {"num_matched_cells", r.num_matched_cells},
               {"num_points", r.num_points},
               {"confident_fraction", confident_fraction},
               {"mean_confidence", r.mean_confidence},
               {"epipolar_offset_cells", r.epipolar_offset_cells},
               {"num_epipolar_samples", r.num_epipolar_samples},
               {"confidence_scale", r.confidence_scale}};
  pair.update(RangeMediansJson(r.points));
  std::ostringstream warning;
  if (r.confidence_scale < 1.0) {
    warning << std::setprecision(2) << "the images do not fit the rig: their matches lie "
            << r.epipolar_offset_cells << " cells off the epipolar lines (median of "
            << r.num_epipolar_samples << " samples), so every confidence was scaled by "
            << r.confidence_scale << " (one image shifted or out of sync, or a wrong rig)";
  }
  if (confident_fraction < kFewConfidentFraction) {
    if (!warning.str().empty()) warning << "; ";
    warning << "few confident pixels: " << r.num_points << " of " << r.num_mirror_cells
            << " mirror cells (" << std::lround(100.0 * confident_fraction)
            << "%); the images may be dark, blurred or out of sync, or the rig may not fit them";
  }
  if (!warning.str().empty()) pair["warning"] = warning.str();
  return pair;
}

}  // namespace

json RunStereoReconstructJob(const json& params, const JobContext& context) {
  const StereoReconstructParams parsed = StereoReconstructParamsFromJson(params);
  const StereoRig rig = LoadRig(context.load_result, parsed.rig_job);
  const StereoPairsInput input = ReadStereoPairs(params, context);

  json result = {{"rig", parsed.rig_job},
                 {"method", parsed.method},
                 {"options", parsed.method == "dense" ? DenseStereoOptionsToJson(parsed.dense)
                                                      : StereoReconstructOptionsToJson(parsed.options)},
                 {"pairs", json::array()}};
  dense::StereoPairsOptions options;
  options.use_dense = parsed.method == "dense";
  options.dense = parsed.dense;
  options.sparse = parsed.options;
  options.rectification_tables_dir = context.RectificationTablesDir();
  int num_bad_pairs = 0;
  const auto on_pair = [&](const dense::StereoPairOutcome& outcome) {
    const std::string& name = outcome.names->name;
    json pair;
    if (outcome.sparse) {
      pair = PairJson(name, *outcome.sparse);
      context.Log("pair " + name + ": " + std::to_string(outcome.sparse->num_matches) +
                  " matches, " + std::to_string(outcome.sparse->points.size()) + " points");
    } else {
      pair = DensePairJson(name, *outcome.dense);
      num_bad_pairs += pair.contains("warning");
      pair["range_tiff"] = outcome.range_tiff;
      pair["range_png"] = outcome.range_png;
      context.Log(
          "pair " + name + ": " + std::to_string(outcome.dense->num_points) + " points of " +
          std::to_string(outcome.dense->num_mirror_cells) + " mirror cells" +
          (pair.contains("warning") ? " (" + pair["warning"].get<std::string>() + ")" : ""));
    }
    if (!outcome.cloud_file.empty()) pair["artifact"] = outcome.cloud_file;
    if (outcome.placed) pair["placed"] = *outcome.placed;
    result["pairs"].push_back(pair);
  };
  if (!input.input.is_null()) result["input"] = input.input;
  const dense::StereoPairsReport report = dense::ReconstructStereoPairs(
      rig, input.read, input.pairs, PlacePairs(parsed, input.pairs, context), options,
      context.output_dir, on_pair, context.progress);
  result["num_points"] = report.num_points;
  if (report.trajectory) {
    json trajectory = {{"source", report.trajectory->source},
                       {"num_pairs_placed", report.trajectory->num_pairs_placed}};
    if (!report.trajectory->warning.empty()) trajectory["warning"] = report.trajectory->warning;
    result["trajectory"] = trajectory;
  }
  if (!report.artifact.empty()) result["artifact"] = report.artifact;
  if (report.clouds_merged) result["clouds_merged"] = *report.clouds_merged;
  if (report.merged_points_per_m2) result["merged_points_per_m2"] = *report.merged_points_per_m2;
  if (report.grid) {
    result["grid"] = {{"rows", report.grid->rows},
                      {"cols", report.grid->cols},
                      {"step_rad", report.grid->step_rad},
                      {"num_disparities", report.grid->num_disparities}};
  }
  if (num_bad_pairs > 0) {
    result["warning"] = std::to_string(num_bad_pairs) + " of " + std::to_string(input.pairs.size()) +
                        " pairs gave few confident pixels (see each pair's warning)";
  }
  return result;
}

void CheckImagesFitRig(const json& params, const SubmissionInputs& inputs) {
  if (!params.contains("rig") || !params["rig"].is_string() || !inputs.load_result) return;
  const std::string rig_job = params["rig"].get<std::string>();
  StereoRig rig;
  try {
    rig = LoadRig(inputs.load_result, rig_job);
  } catch (const std::exception&) {
    return;
  }
  const CameraModel* cameras[2] = {&rig.cam0, &rig.cam1};
  std::ostringstream sizes;
  int num_bad = 0;
  for (const SubmissionInputs::Image& image : inputs.images) {
    for (int c = 0; c < 2; ++c) {
      const std::string prefix = "cam" + std::to_string(c) + "/";
      if (image.name.rfind(prefix, 0) != 0 || image.width <= 0) continue;
      if (image.width == cameras[c]->width && image.height == cameras[c]->height) continue;
      if (num_bad++ < 3) {
        sizes << (num_bad > 1 ? "; " : " ") << image.name << " is " << image.width << "x"
              << image.height << " but the rig's cam" << c << " is calibrated for "
              << cameras[c]->width << "x" << cameras[c]->height;
      }
    }
  }
  OMNIRIG_CHECK(num_bad == 0, num_bad << " image(s) do not fit the rig of job " << rig_job << ":"
                                      << sizes.str()
                                      << " (calibrate the cameras at this image size, or "
                                         "upload images of the calibrated size)");
}

JobType StereoReconstructJobType() {
  JobType type;
  type.name = "stereo_reconstruct";
  type.validate = [](const json& params) { StereoReconstructParamsFromJson(params); };
  type.referenced_jobs = [](const json& params) {
    const StereoReconstructParams parsed = StereoReconstructParamsFromJson(params);
    std::vector<JobReference> references = {{parsed.rig_job, "relative_pose", "rig"}};
    if (parsed.trajectory_job) references.push_back({*parsed.trajectory_job, "slam", "trajectory"});
    return references;
  };
  type.check_inputs = [](const json& params, const SubmissionInputs& inputs) {
    if (const auto recording = RecordingInputFromJson(params, 2)) {
      CheckRecordingInput(*recording, inputs);
      return;
    }
    CheckImagesFitRig(params, inputs);
  };
  type.run = RunStereoReconstructJob;
  return type;
}

json EpipolarCurveJson(const json& relative_pose_result, int from_camera, double u, double v) {
  OMNIRIG_CHECK(from_camera == 0 || from_camera == 1,
                "'from' must be cam0 or cam1, got camera " << from_camera);
  OMNIRIG_CHECK(std::isfinite(u) && std::isfinite(v), "'u' and 'v' must be finite numbers");
  const StereoRig rig = WithErrorPrefix("this job's result holds no stereo rig: ",
                                        [&] { return RigFromJson(relative_pose_result); });
  json polylines = json::array();
  for (const Polyline2d& curve : EpipolarCurve(rig, from_camera, Eigen::Vector2d(u, v))) {
    json line = json::array();
    for (const Eigen::Vector2d& p : curve) line.push_back({p.x(), p.y()});
    polylines.push_back(std::move(line));
  }
  return {{"from", from_camera == 0 ? "cam0" : "cam1"},
          {"to", from_camera == 0 ? "cam1" : "cam0"},
          {"pixel", {u, v}},
          {"polylines", std::move(polylines)}};
}

}  // namespace omnirig::api
