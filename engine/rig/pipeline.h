#pragma once
// The relative pose of a stereo rig from image pairs of a shared board, as the `relative_pose`
// job and `omnirig relpose` run it: read -> detect -> calibrate each camera from its own images
// (or take calibrations made elsewhere) -> the joint fit, with a named intrinsics model or the
// model chosen by cross-validation (relpose_model_select.h).
//
// Each camera is calibrated with Calibrate (engine/calib/calibrate.h) from the detections made
// here, not with CalibrateImages: its second detection pass with the model would add views
// the rig's figures were not measured with.

#include <array>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "engine/calib/board.h"
#include "engine/calib/calibrate.h"
#include "engine/features/image.h"
#include "engine/rig/relative_pose.h"
#include "engine/rig/relpose_model_select.h"
#include "engine/util/image_pairs.h"
#include "engine/util/progress.h"

namespace omnirig {

// A camera calibrated elsewhere: its model and its calibration's used views (corners and ids).
// The views that are not one of the pairs' own images join the joint fit as single-camera
// views (a camera chain in the manner of Kalibr) when the model refines the intrinsics.
struct GivenCamera {
  CameraModel model;
  std::vector<CalibrationView> views;
};

// The names "intrinsics_model" takes: "auto" and the candidates' (relpose_model_select.h).
inline constexpr const char* kRigIntrinsicsModelNames[] = {
    "auto", "fixed", "tangential_fixed", "tangential_free_cam0", "tangential_free_cam1", "free"};
// Whether the model needs the cameras calibrated from the pairs' own images (the tangential
// models recalibrate with k3 = k4 = 0; given calibrations are never redone).
bool RigIntrinsicsModelNeedsOwnCalibration(const std::string& name);

struct RigFromImagesOptions {
  // "auto": each candidate of AutoRigIntrinsicsModels (only "fixed" and "free" with given
  // cameras) is fitted and scored by leave-one-pair-out prediction, and the simplest within one
  // standard error of the best is used. A candidate's name: that model alone.
  std::string intrinsics_model = "auto";
  // The joint fit's options; relpose.fixed_intrinsics is the set the models start from, and
  // refine_intrinsics and the fixed sets are replaced by the model's.
  RelativePoseOptions relpose;

  void Check() const;
};

// A camera the fit started from: given, or calibrated here from its images of the pairs.
struct RigCameraSource {
  CameraModel model;
  std::optional<CalibrationReport> calibration;  // nullopt: the given camera
};

struct RigFromImagesReport {
  RelativePoseReport fit;        // the model's fit (its success is true)
  std::string intrinsics_model;  // the model used (auto: the one chosen)
  bool intrinsics_refined = false;
  std::array<RigCameraSource, 2> cameras;
  std::optional<RigModelSelection> selection;  // "auto": every candidate's score
};

// Reads `dir / pair.cam0` and `dir / pair.cam1` of every pair (grey), checks that each camera's
// images have its given calibration's size (or, without one, its first image's), detects the
// board, calibrates the cameras that were not given, and fits the rig. `given`: both cameras
// or neither. `log` (optional) receives a line per step. Progress: "read", "detect", the
// calibrations' stages, then the fit's or the model selection's, ending on the fit's summary.
// Throws InvalidArgument for bad input (before any detection where it can: unreadable images,
// wrong sizes) and when no rig can be estimated ("no relative pose: ..."), Cancelled.
RigFromImagesReport EstimateRigFromImages(const std::filesystem::path& dir,
                                          const std::vector<ImagePairNames>& pairs,
                                          const BoardSpec& board,
                                          const std::array<std::optional<GivenCamera>, 2>& given,
                                          const RigFromImagesOptions& options,
                                          const ProgressSink& progress,
                                          const std::function<void(const std::string&)>& log = {});
// As above, the images read through `read` (e.g. frames of a recording).
RigFromImagesReport EstimateRigFromImages(const ImageReader& read,
                                          const std::vector<ImagePairNames>& pairs,
                                          const BoardSpec& board,
                                          const std::array<std::optional<GivenCamera>, 2>& given,
                                          const RigFromImagesOptions& options,
                                          const ProgressSink& progress,
                                          const std::function<void(const std::string&)>& log = {});

}  // namespace omnirig
