#pragma once
// Consistency of a detected checkerboard grid: every corner against where its grid neighbours
// predict it.
//
// Why: OpenCV's classic detector links the quads of small squares by their nearest vertices; at a
// board's edge it can average the vertices of two different quads and put an inner corner
// halfway along a square's side (api/relpose_job_test's render cam1/pair_007: corner 47 at
// (539, 280), 3.9 px from the truth, between the true corners 47 and 39; its internal 2x2
// cornerSubPix cannot move it that far). omnirig's refinement cannot recover either: its window
// is sized from the distance to the nearest neighbour, which the wrong corner itself halves (a 2 px
// half-window; cornerSubPix returns its start when the iterate leaves the window, and the
// curved-junction fit refuses so small a disc). The sector-based detector has its own failures
// where a board's corner meets an occluder (KaidanOmni13 and 15: the last corner 7.6 and 4.3 px
// off, on the board's outer edge). One such corner biases a calibration and makes a stereo pair
// look unsynchronised.
//
// Model: along a board row or column the corners lie on the image of a straight line (a conic on
// a catadioptric or fisheye image) with a smoothly varying spacing, so each coordinate is locally
// a smooth function of the grid index. A corner's prediction along one line is the quadratic
// fitted by least squares to the num_neighbours nearest corners of that line (offsets -1, +1, -2,
// +2, ...; at a grid's edge it extrapolates from one side). Its deviation is the smaller of its
// distances to the row's and the column's prediction: a wrong corner is far from both, while a
// good corner next to a wrong one is disturbed along one line only.

#include <vector>

#include <Eigen/Core>

namespace omnirig {

struct GridCheckOptions {
  // A corner is inconsistent when its deviation exceeds
  //   max(min_deviation_px, max_relative_deviation * local square size in pixels).
  // Largest deviation of clean corners, in squares (and pixels), measured with these defaults:
  //   renders 1024x768, 20 views of the 8x6 board: exact corners 0.037 (0.70 px); detected,
  //     noise-free 0.038, image noise 2 grey levels 0.039 (0.73 px), 19 grey levels 0.126
  //     (0.91 px: squares of 6 px);
  //   real sets, omnirig's detector: ocamcalib VMR 0.119 (5.6 px on 47 px squares), KaidanOmni
  //     0.187 (2.0 px) once its two wrong corners are fixed, fisheye pairs 0.070 (2.2 px);
  //   other tools' corners: OpenCV's omnidir tutorial files 0.20 (including corners with 4 px
  //     calibration residuals), the OCamCalib toolbox's VMR corners 0.14.
  // Wrong corners: 0.33 (bench_detect_bias, 11x8 board, noise-free, view 23: corner 1 2.6 px
  // off, the same quad mislinking), 0.45 (the reproduction case, 3.5 px on 7.9 px squares), 0.55
  // and 0.99 (KaidanOmni15 and 13). Model error grows with the square (third derivative of the
  // grid), the noise of a prediction does not, hence a relative limit with a floor in pixels.
  double min_deviation_px = 1.0;
  double max_relative_deviation = 0.3;
  // Corners used along each line: the nearest ones, alternating sides.
  int num_neighbours = 4;
  // At most this many corners are flagged (worst first); the search stops there.
  int max_flagged = 1000;

  void Check() const;
};

// One corner's prediction from its neighbours.
struct GridCornerPrediction {
  bool valid = false;  // at least one line (row or column) predicts it
  // The mean of the row's and the column's predictions (those available), pixels.
  Eigen::Vector2d predicted_px = Eigen::Vector2d::Zero();
  // min over the available lines of |corner - line prediction|, pixels (0 when !valid).
  double deviation_px = 0.0;
  // Distance from the prediction to the nearest usable 4-neighbour: the local square size.
  double square_px = 0.0;
};

// Predictions for every corner of a row-major grid of cols x rows corners (grid.size() ==
// cols * rows) from its usable neighbours (usable[i] false leaves corner i out of every
// prediction; an empty `usable` means all). Corners that are not usable get a prediction too.
// Each line's quadratic uses the num_neighbours usable corners nearest along it.
std::vector<GridCornerPrediction> PredictFromGridNeighbours(
    const std::vector<Eigen::Vector2d>& grid, int cols, int rows,
    const std::vector<bool>& usable = {}, int num_neighbours = 4);

// The limit of `options` at a corner whose local square is square_px (pixels).
double GridDeviationLimitPx(const GridCheckOptions& options, double square_px);

// The inconsistent corners of a full grid, worst first: repeatedly the corner whose deviation
// exceeds its limit by the largest factor is flagged and left out of its neighbours'
// predictions, until every remaining corner is consistent (or max_flagged are flagged).
std::vector<int> FindInconsistentCorners(const std::vector<Eigen::Vector2d>& grid, int cols,
                                         int rows, const GridCheckOptions& options);

}  // namespace omnirig
