#pragma once
// Calibration from a long input (a recording's frames, a large folder): a cheap board test on
// every frame, full detection only on the candidates that differ from the ones already kept, and
// a choice of the views that cover the mirror and the board's poses best.
//
// 1. Screening: each frame, in grey at full size, goes through OpenCV's classic chessboard
//    detector with CALIB_CB_FAST_CHECK (a quad test that rejects a frame without a board) and
//    without CALIB_CB_ADAPTIVE_THRESH: on the 1280x1024 renders of bench_calib_recording it takes
//    0.02 s with a board and 0.05 s without, where the adaptive thresholds took 60-78 s on boards
//    half hidden by the mirror's hole (and at half or three-quarter size it missed most boards).
//    A frame where it finds no whole board is "no_board".
//    ChArUco boards and AprilGrids, whose full detector takes partial views, skip the cheap test:
//    every frame goes to full detection.
// 2. Near duplicates: at 20 Hz consecutive frames show the board where it was. In input order, a
//    candidate whose screened corners lie within near_duplicate_fraction of the image's smaller
//    side (mean distance over the board's corners, either numbering of the board) of a candidate
//    already kept is "near_duplicate_of" that one.
// 3. Full detection (DetectBoard, the cheap variants) on the kept candidates.
// 4. Selection: greedy on the corners' coverage of the mirror disk (5 rings x 16 sectors around the
//    image centre; each cell's gain grows as the square root of its corner count, so that empty
//    cells come first and then the thinnest), the first half of max_views on that alone; a first
//    calibration on those gives every detected view's board pose, and the second half also
//    favours views whose tilt (0-15, 15-30, 30-45, 45+ degrees to the line of sight) and distance
//    (thirds of the range seen) are rare among the views chosen. The rest is "not_selected".

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "engine/calib/board.h"
#include "engine/calib/calibrate.h"
#include "engine/util/progress.h"

namespace omnirig {

struct FrameSelectionOptions {
  // An input of more than long_input_frames images (and more than max_views) is screened and at
  // most max_views views are calibrated; a shorter one has every view detected and used, as an
  // image folder is. 0: no cap (every frame detected fully and every view used, whatever the
  // input's length).
  int max_views = 50;
  // Where the long path starts: 15 s of a recording at 20 Hz. A folder of a few dozen images is
  // detected view by view with every variant and the re-detection pass: OpenCV's classic
  // detector, which screens a long input, misses boards on catadioptric images that DetectBoard
  // finds, and only a long input has frames to spare.
  int long_input_frames = 300;
  // Of the image's smaller side: the mean corner distance under which two frames' boards are the
  // same view.
  double near_duplicate_fraction = 0.04;

  void Check() const;
};

// The cheap test on one frame (8-bit grey): the whole board's corners (board order up to the
// board's turn), empty when no whole board is found.
std::vector<Eigen::Vector2d> ScreenFrame(const cv::Mat& grey, const BoardSpec& board);

// The mean distance of two full sets of board corners, the better of the two numberings.
double BoardShift(const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b);

// For each frame with corners (the others are skipped), in order: -1 when it is kept, else the
// index of the kept frame it nearly duplicates (BoardShift below `threshold_px`).
std::vector<int> MarkNearDuplicates(const std::vector<std::vector<Eigen::Vector2d>>& corners,
                                    double threshold_px);

// Chooses at most max_views of `views` (those with detection.found), as step 4 above. Returns the
// indices into `views`, in input order. Views beyond the cap are only compared, never dropped
// when there are max_views or fewer.
std::vector<int> SelectViews(const std::vector<CalibrationView>& views, int width, int height,
                             const BoardSpec& board, int max_views,
                             const CalibrationOptions& options);

}  // namespace omnirig
