#include "engine/rig/pipeline.h"

#include <algorithm>
#include <iterator>
#include <sstream>
#include <utility>

#include <opencv2/imgcodecs.hpp>

#include "engine/calib/detect.h"
#include "engine/util/check.h"
#include "engine/util/progress_range.h"

namespace omnirig {
namespace {

using FixedSet = std::array<bool, UnifiedIntrinsics::kNumParams>;
using Log = std::function<void(const std::string&)>;

void Write(const Log& log, const std::string& line) {
  if (log) log(line);
}

std::vector<cv::Mat> ReadImages(const ImageReader& read,
                                const std::vector<std::string>& names,
                                const ProgressSink& progress) {
  std::vector<cv::Mat> images;
  for (size_t i = 0; i < names.size(); ++i) {
    progress.ThrowIfCancelled();
    cv::Mat image = read(names[i], cv::IMREAD_GRAYSCALE);
    OMNIRIG_CHECK(!image.empty(), "image " << names[i]
                                           << " cannot be read (missing, truncated or "
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
    if (num_bad++ < 5)
      os << " " << names[i] << " is " << images[i].cols << "x" << images[i].rows << ";";
  }
  OMNIRIG_CHECK(num_bad == 0, num_bad << " image(s) differ from " << what << " (" << width << "x"
                                      << height << "):" << os.str());
}

// Each camera's images, all of its calibration's size (or of its first image's without one).
std::array<std::vector<cv::Mat>, 2> ReadCheckedImages(
    const ImageReader& read, const std::array<std::vector<std::string>, 2>& names,
    const std::array<std::optional<GivenCamera>, 2>& given, const ProgressSink& progress) {
  std::array<std::vector<cv::Mat>, 2> images;
  for (int c = 0; c < 2; ++c) {
    images[c] = ReadImages(read, names[c], SubRange(progress, 0.05 * c, 0.05 * (c + 1)));
    const int width = given[c] ? given[c]->model.width : images[c][0].cols;
    const int height = given[c] ? given[c]->model.height : images[c][0].rows;
    CheckImageSizes(images[c], names[c], width, height,
                    given[c] ? "cam" + std::to_string(c) + "'s calibration"
                             : "cam" + std::to_string(c) + "'s first image");
  }
  return images;
}

std::vector<BoardDetection> DetectAll(const std::vector<cv::Mat>& images,
                                      const std::vector<std::string>& names, const BoardSpec& board,
                                      const ProgressSink& progress) {
  std::vector<BoardDetection> detections;
  for (size_t i = 0; i < images.size(); ++i) {
    progress.ThrowIfCancelled();
    detections.push_back(DetectBoard(images[i], board, DetectOptions()));
    progress.Report((i + 1.0) / images.size(), "detect",
                    names[i] + (detections.back().found ? ": found" : ": not found"));
  }
  return detections;
}

// One camera calibrated from its images of the pairs. The same intrinsics stay fixed here as
// in the joint refinement (`fixed`), so that both steps fit one model.
RigCameraSource CalibrateFromOwnImages(const std::vector<std::string>& names,
                                       const std::vector<BoardDetection>& detections,
                                       const cv::Size& size, const BoardSpec& board,
                                       const FixedSet& fixed, int num_threads,
                                       const ProgressSink& progress) {
  std::vector<CalibrationView> views;
  for (size_t i = 0; i < names.size(); ++i) views.push_back({names[i], detections[i]});
  CalibrationOptions options;
  options.fixed = fixed;
  options.num_threads = std::max(1, num_threads);
  RigCameraSource source;
  source.calibration = Calibrate(views, size.width, size.height, board, options, progress);
  source.model = source.calibration->camera;
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
// those that are not one of the pairs' own images.
void AddCalibrationViews(const std::array<std::optional<GivenCamera>, 2>& given,
                         std::vector<StereoBoardPair>* board_pairs) {
  const size_t num_pairs = board_pairs->size();
  for (int c = 0; c < 2; ++c) {
    if (!given[c]) continue;
    for (const CalibrationView& view : given[c]->views) {
      bool own = false;
      for (size_t i = 0; i < num_pairs && !own; ++i) {
        own =
            SameDetection(view.detection, c == 0 ? (*board_pairs)[i].cam0 : (*board_pairs)[i].cam1);
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

void LogBaseline(const RelativePoseReport& report, const Log& log) {
  Write(log, "baseline " + std::to_string(report.baseline_m * 1e3) + " mm from " +
                 std::to_string(report.num_pairs_used) + " pairs, RMS " +
                 std::to_string(report.rms_px) + " px");
}

// The named candidate model for the fixed set `base`.
RigIntrinsicsModel NamedModel(const std::string& name, const FixedSet& base) {
  std::vector<RigIntrinsicsModel> models = StandardRigIntrinsicsModels(base);
  for (const RigIntrinsicsModel& model : PerCameraTangentialModels(base)) models.push_back(model);
  for (const RigIntrinsicsModel& model : models) {
    if (model.name == name) return model;
  }
  throw InvalidArgument("unknown intrinsics model '" + name + "'");
}

// The images and detections of both cameras, and the cameras the fits start from.
struct DetectedPairs {
  std::array<std::vector<std::string>, 2> names;
  std::array<cv::Size, 2> sizes;
  std::array<std::vector<BoardDetection>, 2> detections;
  std::array<RigCameraSource, 2> cameras;
  std::vector<StereoBoardPair> board_pairs;  // the pairs, then the given views
};

// "auto": the candidate models (AutoRigIntrinsicsModels), each camera from its own calibration
// with the model's fixed set (a camera whose tangential terms the model fixes is calibrated
// again with k3 = k4 = 0, once), scored by cross-validation; the chosen one's fit is the result.
RigFromImagesReport RunAutoModel(const BoardSpec& board, bool cameras_given,
                                 const RelativePoseOptions& options, const DetectedPairs& data,
                                 const ProgressSink& progress, const Log& log) {
  const FixedSet& base = options.fixed_intrinsics;
  std::vector<RigModelCandidate> candidates;
  std::vector<std::array<const RigCameraSource*, 2>> sources;
  std::array<std::optional<RigCameraSource>, 2> recalibrated;
  // Given calibrations are not redone: their own intrinsics kept, or refined with the rig.
  std::vector<RigIntrinsicsModel> models = AutoRigIntrinsicsModels(base);
  if (cameras_given) {
    models.erase(std::remove_if(models.begin(), models.end(),
                                [](const RigIntrinsicsModel& model) {
                                  return model.name != "fixed" && model.name != "free";
                                }),
                 models.end());
  }
  for (const RigIntrinsicsModel& model : models) {
    std::array<const RigCameraSource*, 2> source{};
    for (int c = 0; c < 2; ++c) {
      if (model.CalibrationFixed(c) == base) {
        source[c] = &data.cameras[c];
        continue;
      }
      // The only other set the candidates use: base with k3 = k4 = 0.
      if (!recalibrated[c]) {
        Write(log, "calibrating cam" + std::to_string(c) + " with k3 = k4 = 0");
        recalibrated[c] = CalibrateFromOwnImages(
            data.names[c], data.detections[c], data.sizes[c], board, model.CalibrationFixed(c),
            options.num_threads, SubRange(progress, 0.7 + 0.025 * c, 0.725 + 0.025 * c));
      }
      source[c] = &*recalibrated[c];
    }
    candidates.push_back({model, source[0]->model, source[1]->model});
    sources.push_back(source);
  }
  RigModelSelection selection = SelectRigIntrinsicsModel(board, data.board_pairs, candidates,
                                                         options, SubRange(progress, 0.75, 1.0));
  if (selection.chosen < 0) {
    throw InvalidArgument("no relative pose: " + selection.candidates[0].fit.message);
  }
  const RigModelScore& chosen = selection.candidates[selection.chosen];
  Write(log, "intrinsics model: " + selection.rule);
  LogBaseline(chosen.fit, log);
  // The candidates each ended on their own summary: the run ends on the chosen one's.
  progress.Report(1.0, "done", RelativePoseSummary(chosen.fit));
  RigFromImagesReport report;
  report.fit = chosen.fit;
  report.intrinsics_model = chosen.name;
  report.intrinsics_refined = candidates[selection.chosen].model.refine_intrinsics;
  for (int c = 0; c < 2; ++c) report.cameras[c] = *sources[selection.chosen][c];
  report.selection = std::move(selection);
  return report;
}

}  // namespace

bool RigIntrinsicsModelNeedsOwnCalibration(const std::string& name) {
  return name != "auto" && name != "fixed" && name != "free";
}

void RigFromImagesOptions::Check() const {
  OMNIRIG_CHECK(std::find(std::begin(kRigIntrinsicsModelNames), std::end(kRigIntrinsicsModelNames),
                          intrinsics_model) != std::end(kRigIntrinsicsModelNames),
                "intrinsics_model must be auto, fixed, tangential_fixed, tangential_free_cam0, "
                "tangential_free_cam1 or free, got '"
                    << intrinsics_model << "'");
  relpose.Check();
}

RigFromImagesReport EstimateRigFromImages(const std::filesystem::path& dir,
                                          const std::vector<ImagePairNames>& pairs,
                                          const BoardSpec& board,
                                          const std::array<std::optional<GivenCamera>, 2>& given,
                                          const RigFromImagesOptions& options,
                                          const ProgressSink& progress, const Log& log) {
  return EstimateRigFromImages(FolderImageReader(dir), pairs, board, given, options, progress,
                               log);
}

RigFromImagesReport EstimateRigFromImages(const ImageReader& read,
                                          const std::vector<ImagePairNames>& pairs,
                                          const BoardSpec& board,
                                          const std::array<std::optional<GivenCamera>, 2>& given,
                                          const RigFromImagesOptions& options,
                                          const ProgressSink& progress, const Log& log) {
  options.Check();
  OMNIRIG_CHECK(given[0].has_value() == given[1].has_value(),
                "give both cameras' calibrations or neither");
  OMNIRIG_CHECK(!pairs.empty(), "no image pairs");
  const bool cameras_given = given[0].has_value();
  OMNIRIG_CHECK(!cameras_given || !RigIntrinsicsModelNeedsOwnCalibration(options.intrinsics_model),
                "intrinsics model " << options.intrinsics_model
                                    << " needs the cameras calibrated from the pairs' images");
  const bool automatic = options.intrinsics_model == "auto";
  RelativePoseOptions relpose = options.relpose;
  // "auto" fits every candidate with the candidate's sets; a named model fixes its own, and
  // its calibrations fix what its joint refinement does, per camera.
  const FixedSet base = relpose.fixed_intrinsics;
  if (!automatic) {
    const RigIntrinsicsModel model = NamedModel(options.intrinsics_model, base);
    relpose.refine_intrinsics = model.refine_intrinsics;
    relpose.fixed_intrinsics = model.joint_fixed;
    relpose.cam1_fixed_intrinsics = model.cam1_joint_fixed;
  }
  DetectedPairs data;
  for (const ImagePairNames& pair : pairs) {
    data.names[0].push_back(pair.cam0);
    data.names[1].push_back(pair.cam1);
  }
  // Everything that can refuse the input does so before detection starts.
  const std::array<std::vector<cv::Mat>, 2> images =
      ReadCheckedImages(read, data.names, given, progress);
  for (int c = 0; c < 2; ++c) {
    data.sizes[c] = images[c][0].size();
    data.detections[c] = DetectAll(images[c], data.names[c], board,
                                   SubRange(progress, 0.1 + 0.3 * c, 0.35 + 0.3 * c));
    if (given[c]) {
      data.cameras[c].model = given[c]->model;
      continue;
    }
    Write(log, "calibrating cam" + std::to_string(c) + " from its own images");
    const FixedSet& fixed = c == 1 && relpose.cam1_fixed_intrinsics ? *relpose.cam1_fixed_intrinsics
                                                                    : relpose.fixed_intrinsics;
    data.cameras[c] = CalibrateFromOwnImages(data.names[c], data.detections[c], data.sizes[c],
                                             board, fixed, relpose.num_threads,
                                             SubRange(progress, 0.35 + 0.3 * c, 0.4 + 0.3 * c));
  }
  for (size_t i = 0; i < pairs.size(); ++i) {
    data.board_pairs.push_back({pairs[i].name, data.detections[0][i], data.detections[1][i]});
  }
  AddCalibrationViews(given, &data.board_pairs);
  if (automatic) return RunAutoModel(board, cameras_given, relpose, data, progress, log);
  RigFromImagesReport report;
  report.fit = EstimateRelativePose(data.cameras[0].model, data.cameras[1].model, board,
                                    data.board_pairs, relpose, SubRange(progress, 0.7, 1.0));
  if (!report.fit.success) throw InvalidArgument("no relative pose: " + report.fit.message);
  LogBaseline(report.fit, log);
  report.intrinsics_model = options.intrinsics_model;
  report.intrinsics_refined = relpose.refine_intrinsics;
  report.cameras = std::move(data.cameras);
  return report;
}

}  // namespace omnirig
