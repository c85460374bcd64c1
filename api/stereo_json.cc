#include "api/stereo_json.h"

#include <algorithm>
#include <cmath>
#include <set>

#include <opencv2/imgcodecs.hpp>

#include "api/camera_json.h"
#include "api/relpose_json.h"
#include "engine/stereo/epipolar.h"
#include "engine/util/check.h"

namespace omnirig::api {
namespace {

using nlohmann::json;

const std::set<std::string> kKnownFields = {"rig",
                                            "max_features",
                                            "ratio_test",
                                            "max_epipolar_error_rad",
                                            "mutual_check",
                                            "min_parallax_rad",
                                            "max_reprojection_error_rad",
                                            "keypoint_std_px",
                                            "max_relative_range_std",
                                            "dark_level",
                                            "mask_margin_px"};

double Number(const json& params, const std::string& key) {
  OMNIRIG_CHECK(params[key].is_number(), "field 'params." << key << "' must be a number");
  return params[key].get<double>();
}

int Integer(const json& params, const std::string& key) {
  OMNIRIG_CHECK(params[key].is_number_integer(), "field 'params." << key << "' must be an integer");
  return params[key].get<int>();
}

void ReadNumber(const json& params, const std::string& key, double* value) {
  if (params.contains(key)) *value = Number(params, key);
}

void ReadInteger(const json& params, const std::string& key, int* value) {
  if (params.contains(key)) *value = Integer(params, key);
}

StereoRig LoadRig(const JobContext& context, const std::string& job_id) {
  OMNIRIG_CHECK(static_cast<bool>(context.load_result),
                "this job cannot read other jobs' results (no result loader)");
  const json result = context.load_result(job_id);
  try {
    return RigFromJson(result);
  } catch (const InvalidArgument& e) {
    throw InvalidArgument("job " + job_id +
                          " holds no stereo rig (is it a relative_pose job?): " + e.what());
  }
}

cv::Mat ReadImage(const JobContext& context, const std::string& name) {
  const cv::Mat image = cv::imread((context.dataset_dir / name).string(), cv::IMREAD_COLOR);
  OMNIRIG_CHECK(!image.empty(), "cannot read image '" << name << "'");
  return image;
}

double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  std::nth_element(values.begin(), values.begin() + values.size() / 2, values.end());
  return values[values.size() / 2];
}

std::string SafeArtifactName(const std::string& pair_name) {
  std::string out = "cloud_";
  for (char c : pair_name) out += (c == '/' || c == '.' || c == '\\') ? '_' : c;
  return out + ".ply";
}

json PairJson(const std::string& name, const StereoPairReport& report) {
  std::vector<double> ranges, stds;
  for (const StereoPoint& p : report.points) {
    ranges.push_back(p.point_in_cam0.norm());
    stds.push_back(p.range_std_m);
  }
  return {{"name", name},
          {"num_keypoints", {report.num_keypoints0, report.num_keypoints1}},
          {"num_candidates", report.num_candidates},
          {"num_matches", report.num_matches},
          {"num_points", report.points.size()},
          {"rejected",
           {{"parallax", report.num_rejected_parallax},
            {"reprojection", report.num_rejected_reprojection},
            {"uncertain", report.num_rejected_uncertain}}},
          {"median_range_m", Median(ranges)},
          {"median_range_std_m", Median(stds)}};
}

}  // namespace

StereoReconstructParams StereoReconstructParamsFromJson(const json& params) {
  OMNIRIG_CHECK(params.is_object(), "'params' must be a JSON object");
  for (const auto& [key, value] : params.items()) {
    OMNIRIG_CHECK(kKnownFields.count(key) > 0, "unknown field 'params." << key << "'");
  }
  StereoReconstructParams out;
  OMNIRIG_CHECK(params.contains("rig"),
                "missing field 'params.rig' (the id of a succeeded relative_pose job)");
  OMNIRIG_CHECK(params["rig"].is_string() && !params["rig"].get<std::string>().empty(),
                "field 'params.rig' must be a job id (a non-empty string)");
  out.rig_job = params["rig"].get<std::string>();
  StereoReconstructOptions& o = out.options;
  ReadInteger(params, "max_features", &o.max_features);
  ReadNumber(params, "ratio_test", &o.ratio_test);
  ReadNumber(params, "max_epipolar_error_rad", &o.max_epipolar_error_rad);
  if (params.contains("mutual_check")) {
    OMNIRIG_CHECK(params["mutual_check"].is_boolean(),
                  "field 'params.mutual_check' must be true or false");
    o.mutual_check = params["mutual_check"].get<bool>();
  }
  ReadNumber(params, "min_parallax_rad", &o.min_parallax_rad);
  ReadNumber(params, "max_reprojection_error_rad", &o.max_reprojection_error_rad);
  ReadNumber(params, "keypoint_std_px", &o.keypoint_std_px);
  ReadNumber(params, "max_relative_range_std", &o.max_relative_range_std);
  ReadNumber(params, "dark_level", &o.dark_level);
  ReadInteger(params, "mask_margin_px", &o.mask_margin_px);
  o.Check();
  return out;
}

json StereoReconstructOptionsToJson(const StereoReconstructOptions& o) {
  return {{"max_features", o.max_features},
          {"ratio_test", o.ratio_test},
          {"max_epipolar_error_rad", o.max_epipolar_error_rad},
          {"mutual_check", o.mutual_check},
          {"min_parallax_rad", o.min_parallax_rad},
          {"max_reprojection_error_rad", o.max_reprojection_error_rad},
          {"keypoint_std_px", o.keypoint_std_px},
          {"max_relative_range_std", o.max_relative_range_std},
          {"dark_level", o.dark_level},
          {"mask_margin_px", o.mask_margin_px}};
}

json RunStereoReconstructJob(const json& params, const JobContext& context) {
  const StereoReconstructParams parsed = StereoReconstructParamsFromJson(params);
  const StereoRig rig = LoadRig(context, parsed.rig_job);
  const std::vector<ImagePairNames> pairs = MatchImagePairs(context.image_names);

  json result = {{"rig", parsed.rig_job},
                 {"options", StereoReconstructOptionsToJson(parsed.options)},
                 {"pairs", json::array()}};
  std::vector<StereoPoint> all_points;
  for (size_t k = 0; k < pairs.size(); ++k) {
    context.progress.ThrowIfCancelled();
    const cv::Mat image0 = ReadImage(context, pairs[k].cam0);
    const cv::Mat image1 = ReadImage(context, pairs[k].cam1);
    StereoPairReport report;
    try {
      report =
          ReconstructStereoPair(rig, image0, image1, parsed.options,
                                SubRange(context.progress, static_cast<double>(k) / pairs.size(),
                                         static_cast<double>(k + 1) / pairs.size()));
    } catch (const InvalidArgument& e) {
      throw InvalidArgument("pair '" + pairs[k].name + "': " + e.what());
    }
    json pair = PairJson(pairs[k].name, report);
    if (pairs.size() > 1) {
      const std::string artifact = SafeArtifactName(pairs[k].name);
      WriteColoredPly(context.output_dir / artifact, report.points);
      pair["artifact"] = artifact;
    }
    context.Log("pair " + pairs[k].name + ": " + std::to_string(report.num_matches) +
                " matches, " + std::to_string(report.points.size()) + " points");
    result["pairs"].push_back(pair);
    all_points.insert(all_points.end(), report.points.begin(), report.points.end());
  }
  result["num_points"] = all_points.size();
  // Each pair's points are in that pair's own cam0 frame: merged, the pairs of a moving rig
  // would pile up into an unreadable blob. One pair makes cloud.ply; several stay apart (the
  // result's artifact is the first pair's cloud), since nothing here places them in one frame.
  if (pairs.size() == 1) {
    WriteColoredPly(context.output_dir / "cloud.ply", all_points);
    result["artifact"] = "cloud.ply";
  } else if (!pairs.empty()) {
    result["artifact"] = result["pairs"][0]["artifact"];
    result["clouds_merged"] = false;
  }
  context.progress.Report(1.0, "done", std::to_string(all_points.size()) + " points from " +
                                           std::to_string(pairs.size()) + " pair(s)");
  return result;
}

void RegisterStereoReconstructJobType() {
  JobType type;
  type.name = "stereo_reconstruct";
  type.validate = [](const json& params) { StereoReconstructParamsFromJson(params); };
  type.referenced_job_type = "relative_pose";
  type.referenced_jobs = [](const json& params) {
    return std::vector<std::string>{StereoReconstructParamsFromJson(params).rig_job};
  };
  type.run = RunStereoReconstructJob;
  RegisterJobType(std::move(type));
}

json EpipolarCurveJson(const json& relative_pose_result, int from_camera, double u, double v) {
  OMNIRIG_CHECK(from_camera == 0 || from_camera == 1,
                "'from' must be cam0 or cam1, got camera " << from_camera);
  OMNIRIG_CHECK(std::isfinite(u) && std::isfinite(v), "'u' and 'v' must be finite numbers");
  StereoRig rig;
  try {
    rig = RigFromJson(relative_pose_result);
  } catch (const InvalidArgument& e) {
    throw InvalidArgument(std::string("this job's result holds no stereo rig: ") + e.what());
  }
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
