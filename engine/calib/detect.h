#pragma once
// Detection of a calibration board's corners in a (strongly distorted) omnidirectional image.
//
// Checkerboards are found fully automatically: OpenCV's detectors run on the image and on
// contrast-normalised and upsampled versions; a candidate must have every corner (sub-boards
// are rejected by the count and the board's extent), a consistent row-major ordering (no
// flipped or mirrored grids) and is refined to sub-pixel with a window adapted to the local
// square size: cornerSubPix, then a fit of the corner's X-junction with curved edges; then every
// corner is checked against its grid neighbours (grid_check.h) and a wrong one refined again from
// their prediction or left out. With a model from an earlier calibration, or with the four outer
// corners given by the user, every corner is predicted and refined instead (the paper's tool's
// hint path). ChArUco boards and Kalibr's AprilGrids go through OpenCV aruco and may be
// partial.

#include <array>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "engine/calib/board.h"
#include "engine/calib/grid_check.h"
#include "engine/geometry/camera_model.h"
#include "engine/geometry/rigid3.h"

namespace omnirig {

struct BoardDetection {
  bool found = false;
  std::string reason;  // why not found (empty when found)
  // Pixel positions (centre of the top-left pixel is (0, 0)) and the index of each corner in
  // BoardSpec::ObjectPoints().
  std::vector<Eigen::Vector2d> corners_px;
  std::vector<int> corner_ids;
  std::string method;  // which detector found it ("sb", "classic", "hint", "model", "charuco",
                       // "aprilgrid")
  // The grid check (DetectOptions::check_grid): corners it refined again from their
  // neighbours' prediction, and the ids it left out because they still disagreed.
  int num_rerefined_corners = 0;
  std::vector<int> dropped_corner_ids;
};

struct DetectOptions {
  // Sub-pixel refinement of every corner.
  bool refine_subpixel = true;
  // After cornerSubPix, fit a model of the blurred X-junction with curved edges to the pixels
  // around each corner (corner_fit.h): cornerSubPix alone is pulled to the convex side of the
  // edges a mirror bends (radially outward, +0.02 px on average on the synthetic renders). Off only
  // to measure that bias.
  bool fit_corner_model = true;
  // After the refinement of an automatically found checkerboard, check every corner against
  // where its row and column neighbours predict it (grid_check.h). An inconsistent corner (e.g.
  // OpenCV's classic detector averaging the vertices of two different quads) is refined again
  // from the prediction; one that still disagrees is dropped (corner_ids then has a gap, which
  // calibration and relative pose handle), and a view that would lose more than
  // max_dropped_fraction of its corners is rejected with the reason.
  bool check_grid = true;
  GridCheckOptions grid_check;
  double max_dropped_fraction = 0.1;
  // Also try a contrast-equalised image, and (with try_costly_variants) 2x upsampled ones, when
  // the plain image fails.
  bool try_enhanced = true;
  // The attempts that cost most of a second each on a 640x480 image (the sector-based
  // detector's ACCURACY upsampling, the classic detector on the equalised image, the 2x
  // upsampled image), after the cheap ones failed. CalibrateImages turns them off in its first
  // pass and runs them only on the views that growing a partial grid with the model of the other
  // views does not find.
  bool try_costly_variants = true;
  // Allow OpenCV's exhaustive search as the last resort (can take minutes on a large image
  // without the board, hence off by default).
  bool allow_exhaustive = false;
  // A ChArUco detection needs at least this many corners.
  int min_charuco_corners = 6;
  // An AprilGrid detection needs at least this many tags (two: the relative place of two tags
  // tells how their corners are labelled, see DetectAprilgrid).
  int min_aprilgrid_tags = 2;
  // The board's four outer corners given by the user, in this order: corner id 0, id cols-1
  // (end of the first row), id rows*cols-1 (last), id (rows-1)*cols (start of the last row).
  std::optional<std::array<Eigen::Vector2d, 4>> outer_corners_hint_px;
  // With a hint and no model, the hint's corners predict the others through a homography,
  // which the distortion of a mirror bends; with a model (from other views) the prediction
  // goes through the model and a board pose fitted to the hint.
  std::optional<CameraModel> model;

  void Check() const;
};

// Detects `board` in `image` (8-bit grey or BGR). Never throws for a missing board: the result
// says why. Throws InvalidArgument for an empty image or invalid options.
BoardDetection DetectBoard(const cv::Mat& image, const BoardSpec& board,
                           const DetectOptions& options);

// The re-detection pass for views the automatic detector missed, once a model exists from
// other views: takes the grid OpenCV's sector-based detector links around a small seed
// (CALIB_CB_LARGER; at least 40 % of the board's corners), tries every placement and
// orientation of it on the board, fits the board pose with the model, predicts every corner and
// refines it, and keeps the placement that confirms the most corners. Returns found = false with
// a reason otherwise.
BoardDetection RedetectWithModel(const cv::Mat& image, const BoardSpec& board,
                                 const CameraModel& model, const DetectOptions& options);

// Checks a full grid (corner id i at grid[i]): every corner inside the image, no collapsed
// squares, and no sub-board of a larger pattern: beyond the board's outer squares, along the
// grid's predicted continuation, the cells must not continue the checker pattern (each the
// colour of the square two rows inwards, in the board's pitch and phase). A margin of any width,
// a frame of another grey, a hand, glare or the background do not. Returns the reason it fails
// (for a larger board: "the board size looks wrong ... at least COLSxROWS"), or "" when it
// passes.
std::string ValidateBoardGrid(const cv::Mat& image, const BoardSpec& board,
                              const std::vector<Eigen::Vector2d>& grid);

// Predicts every corner of `board` at `cam_from_board` with `model` and refines each in
// `image`; corners that do not project or whose refinement moves too far are left out.
// found requires at least half of the corners. Used by the re-detection pass of Calibrate
// callers and by the hint path.
BoardDetection DetectBoardFromPose(const cv::Mat& image, const BoardSpec& board,
                                   const CameraModel& model, const Rigid3d& cam_from_board,
                                   const DetectOptions& options);

}  // namespace omnirig
