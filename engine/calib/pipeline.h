#pragma once
// The whole calibration of a set of image files, as the CLI and the `calibration` job run it:
// read -> detect (per image, with optional hints) -> calibrate -> overlays.

#include <array>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "engine/calib/calibrate.h"
#include "engine/calib/frame_selection.h"
#include "engine/features/image.h"

namespace omnirig {

// The single-viewpoint check after a calibration (svp.h): the rim predicted from the mirror's
// dimensions and found in an image, or, without them, only found and compared with the
// principal point.
struct SvpOptions {
  std::optional<MirrorRim> mirror;
  std::string image;  // the image to check; empty: the first image used by the calibration
  SvpCheckOptions check;

  void Check() const;
};

struct ImageCalibrationOptions {
  DetectOptions detect;
  CalibrationOptions calibrate;
  // Four outer corners per image name (see DetectOptions::outer_corners_hint_px).
  std::map<std::string, std::array<Eigen::Vector2d, 4>> hints;
  // After a first calibration, views the detector missed are searched again by growing a
  // partial grid with the model (RedetectWithModel), and the calibration is re-run. The first
  // pass then leaves out the detector's costly variants (DetectOptions::try_costly_variants):
  // they run only on the views growing does not find, or on every missed view when too few
  // views for a first calibration were found.
  bool redetect_with_model = true;
  // A long input (more images than selection.long_input_frames and selection.max_views, e.g. a
  // recording's frames) is screened with a cheap board test, near duplicates are skipped, and at
  // most max_views views covering the mirror and the board's poses are calibrated
  // (frame_selection.h); without the second pass above. CalibrationReport::frames says what
  // became of every frame.
  FrameSelectionOptions selection;
  // Overlays: error vectors are drawn this many times longer than they are.
  double overlay_error_scale = 20.0;
  // When set, the single-viewpoint check runs after the calibration and its overlay is written
  // as kSvpOverlayFileName.
  std::optional<SvpOptions> svp;

  void Check() const;
};

inline constexpr const char* kSvpOverlayFileName = "svp_overlay.png";

// Reads `dir / name` for every name, detects the board, calibrates, and (when `overlay_dir` is
// not empty) writes OverlayFileName(name) there, and the SVP check's
// overlay when requested. An SVP check that cannot run (the rim does not project, the image is
// unreadable) leaves its reason in report.svp and does not fail the calibration. Unreadable images
// and images of another size than the first readable one are reported as unused with the
// reason. A long input (ImageCalibrationOptions::selection) is screened and its views chosen;
// report.images then holds the views detected fully and chosen, report.frames every frame.
// Progress: "detect" per image over [0, 0.5], then Calibrate's stages over [0.5, 1]
// (with a "redetect" pass and a second calibration when views were missed).
CalibrationReport CalibrateImages(const std::filesystem::path& dir,
                                  const std::vector<std::string>& names, const BoardSpec& board,
                                  const ImageCalibrationOptions& options,
                                  const std::filesystem::path& overlay_dir,
                                  const ProgressSink& progress);
// As above, the images read through `read` (e.g. frames of a recording).
CalibrationReport CalibrateImages(const ImageReader& read, const std::vector<std::string>& names,
                                  const BoardSpec& board, const ImageCalibrationOptions& options,
                                  const std::filesystem::path& overlay_dir,
                                  const ProgressSink& progress);

// The overlay of one image: detected corners (green circles), the model's reprojections (red
// crosses), error vectors magnified `error_scale` times (yellow), outliers in magenta, and a
// caption with the image's RMS. Works on unused images too (detected corners only).
cv::Mat DrawCalibrationOverlay(const cv::Mat& image, const CalibrationImageReport& report,
                               double error_scale);

// "overlay_<name>.png" with '/' and '\\' replaced by '_' and the image's extension dropped
// (cam0/view_000.png -> overlay_cam0_view_000.png).
std::string OverlayFileName(const std::string& image_name);

}  // namespace omnirig
