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

#include <opencv2/imgcodecs.hpp>

#include "api/camera_json.h"
#include "api/json_fields.h"
#include "api/relpose_job.h"
#include "engine/dense/range_io.h"
#include "engine/estimators/epipolar.h"
#include "engine/geometry/ply.h"
#include "engine/slam/map_io.h"
#include "engine/util/background_task.h"
#include "engine/util/check.h"

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
          {"max_relative_range_std", &o->max_relative_range_std},
          {"dark_level", &o->dark_level},
          {"mask_margin_cells", &o->mask_margin_cells},
          {"max_epipolar_offset_cells", &o->max_epipolar_offset_cells}};
}

// A pair whose confident cells are fewer than this fraction of its mirror cells is reported as
// a bad pair (dark, blurred, out of sync): the room renders give about 0.8, a pair with one
// image shifted by 4 px about 0.3.
constexpr double kFewConfidentFraction = 0.5;

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

// NAME of a pair's range panoramas (NAME_range.tiff): the pair's name without its extension,
// '/' and '\\' replaced by '_'.
std::string RangeBaseName(const std::string& pair_name) {
  std::string out = std::filesystem::path(pair_name).replace_extension().string();
  for (char& c : out) {
    if (c == '/' || c == '\\') c = '_';
  }
  return out;
}

// Each pair's cam0 pose in one world, when a trajectory gives it: a slam job's (frames named as
// the pairs) or the dataset's .tum file (by timestamp when the pairs are named by time, else one
// pose per pair in order, as slam's ground truth).
struct PairPlacement {
  std::string source;                                   // "slam job ID" or "NAME.tum"
  std::vector<std::optional<Rigid3d>> world_from_cam0;  // per pair
  std::string warning;  // why some or all pairs could not be placed
};

PairPlacement PlaceBySlamJob(const std::string& job_id, const std::vector<ImagePairNames>& pairs,
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
  PairPlacement placement{"slam job " + job_id, {}, ""};
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

PairPlacement PlaceByTum(const std::string& file, const std::vector<ImagePairNames>& pairs,
                         const JobContext& context) {
  PairPlacement placement{file, std::vector<std::optional<Rigid3d>>(pairs.size()), ""};
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

std::optional<PairPlacement> PlacePairs(const StereoReconstructParams& parsed,
                                        const std::vector<ImagePairNames>& pairs,
                                        const JobContext& context) {
  if (parsed.trajectory_job) return PlaceBySlamJob(*parsed.trajectory_job, pairs, context);
  std::vector<std::string> tum;
  for (const std::string& name : context.image_names) {
    if (name.size() > 4 && name.compare(name.size() - 4, 4, ".tum") == 0) tum.push_back(name);
  }
  if (tum.empty()) return std::nullopt;
  if (tum.size() > 1) {
    return PairPlacement{tum[0], std::vector<std::optional<Rigid3d>>(pairs.size()),
                         "the dataset holds " + std::to_string(tum.size()) +
                             " .tum trajectories: name a slam job in 'trajectory' instead"};
  }
  return PlaceByTum(tum[0], pairs, context);
}

// Where the pairs' clouds go. Without a trajectory: one pair writes cloud.ply, in its
// cam0 frame; several write cloud_NAME.ply each in its own cam0 frame and no merged cloud (the
// pairs of a moving rig share no frame). With one: cloud_NAME.ply per pair as well, and
// cloud.ply with every placed pair moved into the trajectory's world.
class CloudOutputs {
 public:
  CloudOutputs(const std::filesystem::path& dir, size_t num_pairs,
               std::optional<PairPlacement> placement)
      : dir_(dir), num_pairs_(num_pairs), placement_(std::move(placement)),
        merged_(dir / "cloud.ply") {}

  // Pair k's keys in the result ("artifact", "placed"), on the job's thread.
  void Describe(size_t k, const std::string& pair_name, json* pair) {
    if (num_pairs_ == 1 && !placement_) return;
    (*pair)["artifact"] = SafeArtifactName(pair_name);
    if (!placement_) return;
    const bool placed = placement_->world_from_cam0[k].has_value();
    (*pair)["placed"] = placed;
    num_placed_ += placed;
  }

  // Writes pair k's cloud, and appends it to the merged cloud when it is placed. Dense jobs
  // call it on their writer thread (one pair at a time, in pair order) while the next pair is
  // matched; Finish() only once the last Write() has returned.
  void Write(size_t k, const std::string& pair_name, const PlyCloud& cloud) {
    if (num_pairs_ == 1 && !placement_) {
      WritePly(dir_ / "cloud.ply", cloud);
      return;
    }
    WritePly(dir_ / SafeArtifactName(pair_name), cloud);
    if (!placement_ || !placement_->world_from_cam0[k]) return;
    const Rigid3d& world_from_cam0 = *placement_->world_from_cam0[k];
    PlyCloud in_world = cloud;
    in_world.comment = "omnirig stereo_reconstruct: all placed pairs in the world of " +
                       placement_->source + ", metres";
    for (Eigen::Vector3f& p : in_world.positions) {
      p = (world_from_cam0 * p.cast<double>()).cast<float>();
    }
    merged_.Append(in_world);
  }

  void Add(size_t k, const std::string& pair_name, const PlyCloud& cloud, json* pair) {
    Describe(k, pair_name, pair);
    Write(k, pair_name, cloud);
  }

  void Finish(json* result) {
    if (placement_) {
      json trajectory = {{"source", placement_->source}, {"num_pairs_placed", num_placed_}};
      if (num_placed_ < static_cast<int>(num_pairs_) && placement_->warning.empty()) {
        placement_->warning = std::to_string(num_pairs_ - num_placed_) +
                              " pair(s) have no pose in the trajectory and are not in cloud.ply";
      }
      if (!placement_->warning.empty()) trajectory["warning"] = placement_->warning;
      (*result)["trajectory"] = trajectory;
    }
    if (num_placed_ > 0) {
      merged_.Finish();
      (*result)["artifact"] = "cloud.ply";
      (*result)["clouds_merged"] = true;
    } else if (num_pairs_ == 1) {
      (*result)["artifact"] = "cloud.ply";
    } else if (num_pairs_ > 1) {
      (*result)["artifact"] = (*result)["pairs"][0]["artifact"];
      (*result)["clouds_merged"] = false;
    }
  }

 private:
  std::filesystem::path dir_;
  size_t num_pairs_;
  std::optional<PairPlacement> placement_;
  PlyAppender merged_;
  int num_placed_ = 0;
};

size_t RunSparse(const StereoReconstructParams& parsed, const StereoRig& rig,
                 const std::vector<ImagePairNames>& pairs, const JobContext& context,
                 CloudOutputs* outputs, json* result) {
  size_t num_points = 0;
  for (size_t k = 0; k < pairs.size(); ++k) {
    context.progress.ThrowIfCancelled();
    const cv::Mat image0 = ReadImage(context, pairs[k].cam0);
    const cv::Mat image1 = ReadImage(context, pairs[k].cam1);
    const StereoPairReport report = WithErrorPrefix("pair '" + pairs[k].name + "': ", [&] {
      return ReconstructStereoPair(rig, image0, image1, parsed.options,
                                   SubRange(context.progress, static_cast<double>(k) / pairs.size(),
                                            static_cast<double>(k + 1) / pairs.size()));
    });
    json pair = PairJson(pairs[k].name, report);
    outputs->Add(k, pairs[k].name, SparseCloud(report.points), &pair);
    context.Log("pair " + pairs[k].name + ": " + std::to_string(report.num_matches) +
                " matches, " + std::to_string(report.points.size()) + " points");
    (*result)["pairs"].push_back(pair);
    num_points += report.points.size();
  }
  return num_points;
}

PlyCloud DenseCloud(const std::vector<dense::DensePoint>& points) {
  PlyCloud cloud;
  cloud.comment = "omnirig stereo_reconstruct (dense): points in cam0's frame, metres";
  cloud.has_confidence = true;
  cloud.positions.reserve(points.size());
  cloud.colours.reserve(points.size());
  cloud.confidence.reserve(points.size());
  for (const dense::DensePoint& p : points) {
    cloud.positions.push_back(p.point_in_cam0);
    cloud.colours.push_back(p.rgb);
    cloud.confidence.push_back(p.confidence);
  }
  return cloud;
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

// Writes pair `name`'s panoramas and cloud (on RunDense's writer thread). An error names the
// pair, as the matching's do.
void WriteDensePair(size_t k, const std::string& name, const dense::DensePairResult& pair_result,
                    const std::filesystem::path& dir, CloudOutputs* outputs) {
  try {
    const std::string base = RangeBaseName(name);
    dense::WriteRangeTiff(dir / (base + "_range.tiff"), pair_result.range_m);
    dense::WriteRangePng(dir / (base + "_range.png"), pair_result.range_m);
    outputs->Write(k, name, DenseCloud(pair_result.points));
  } catch (const InvalidArgument& e) {
    throw InvalidArgument("pair '" + name + "': " + e.what());
  } catch (const std::exception& e) {
    throw std::runtime_error("pair '" + name + "': " + e.what());
  }
}

// Pair k's files are written on a background thread while pair k + 1 is read and matched (the
// writing, 0.09 CPU s per 1024x768 pair, runs on one thread, the matching on all: bench_dense).
// At most one pair waits to be written; a failed write stops the job at the next pair, naming
// the pair, and nothing is written twice.
size_t RunDense(const StereoReconstructParams& parsed, const StereoRig& rig,
                const std::vector<ImagePairNames>& pairs, const JobContext& context,
                CloudOutputs* outputs, json* result) {
  context.progress.Report(0.0, "rectify", "building the rectification tables");
  const dense::DenseStereo dense(rig, parsed.dense);
  size_t num_points = 0;
  int num_bad_pairs = 0;
  BackgroundTask writer;
  for (size_t k = 0; k < pairs.size(); ++k) {
    context.progress.ThrowIfCancelled();
    const cv::Mat image0 = ReadImage(context, pairs[k].cam0);
    const cv::Mat image1 = ReadImage(context, pairs[k].cam1);
    auto pair_result = std::make_shared<dense::DensePairResult>(
        WithErrorPrefix("pair '" + pairs[k].name + "': ", [&] {
          return dense.Reconstruct(image0, image1,
                                   SubRange(context.progress, static_cast<double>(k) / pairs.size(),
                                            static_cast<double>(k + 1) / pairs.size()));
        }));
    json pair = DensePairJson(pairs[k].name, *pair_result);
    num_bad_pairs += pair.contains("warning");
    const std::string base = RangeBaseName(pairs[k].name);
    pair["range_tiff"] = base + "_range.tiff";
    pair["range_png"] = base + "_range.png";
    outputs->Describe(k, pairs[k].name, &pair);
    context.Log("pair " + pairs[k].name + ": " + std::to_string(pair_result->num_points) +
                " points of " + std::to_string(pair_result->num_mirror_cells) + " mirror cells" +
                (pair.contains("warning") ? " (" + pair["warning"].get<std::string>() + ")" : ""));
    (*result)["pairs"].push_back(pair);
    num_points += pair_result->points.size();
    writer.Run([k, name = pairs[k].name, pair_result, &context, outputs] {
      WriteDensePair(k, name, *pair_result, context.output_dir, outputs);
    });
  }
  writer.Wait();
  (*result)["grid"] = {{"rows", dense.rectifier().rows()},
                       {"cols", dense.rectifier().cols()},
                       {"step_rad", dense.rectifier().theta_step_rad()},
                       {"num_disparities", dense.num_disparities()}};
  if (num_bad_pairs > 0) {
    (*result)["warning"] = std::to_string(num_bad_pairs) + " of " + std::to_string(pairs.size()) +
                           " pairs gave few confident pixels (see each pair's warning)";
  }
  return num_points;
}

}  // namespace

json RunStereoReconstructJob(const json& params, const JobContext& context) {
  const StereoReconstructParams parsed = StereoReconstructParamsFromJson(params);
  const StereoRig rig = LoadRig(context.load_result, parsed.rig_job);
  const std::vector<ImagePairNames> pairs = MatchImagePairs(context.image_names);

  json result = {{"rig", parsed.rig_job},
                 {"method", parsed.method},
                 {"options", parsed.method == "dense" ? DenseStereoOptionsToJson(parsed.dense)
                                                      : StereoReconstructOptionsToJson(parsed.options)},
                 {"pairs", json::array()}};
  CloudOutputs outputs(context.output_dir, pairs.size(), PlacePairs(parsed, pairs, context));
  const size_t num_points = parsed.method == "dense"
                                ? RunDense(parsed, rig, pairs, context, &outputs, &result)
                                : RunSparse(parsed, rig, pairs, context, &outputs, &result);
  result["num_points"] = num_points;
  outputs.Finish(&result);
  context.progress.Report(1.0, "done", std::to_string(num_points) + " points from " +
                                           std::to_string(pairs.size()) + " pair(s)");
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

void RegisterStereoReconstructJobType() {
  JobType type;
  type.name = "stereo_reconstruct";
  type.validate = [](const json& params) { StereoReconstructParamsFromJson(params); };
  type.referenced_jobs = [](const json& params) {
    const StereoReconstructParams parsed = StereoReconstructParamsFromJson(params);
    std::vector<JobReference> references = {{parsed.rig_job, "relative_pose", "rig"}};
    if (parsed.trajectory_job) references.push_back({*parsed.trajectory_job, "slam", "trajectory"});
    return references;
  };
  type.check_inputs = CheckImagesFitRig;
  type.run = RunStereoReconstructJob;
  RegisterJobType(std::move(type));
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
