#pragma once
// Dense 3D from one pair of a calibrated omnidirectional stereo rig: 360-degree range panoramas
// and dense clouds ("3D perception instantly, without moving", the paper's case for the vertical
// rig). Reads as rectify (spherical_rectification.h) -> mask -> match (OpenCV's semi-global
// matcher along the grid rows, its left-right check, sub-pixel disparity, speckle filter) ->
// confidence (zero-mean normalised cross-correlation of the matched windows) -> range (exact
// triangulation of the two angles, law of sines) with its uncertainty.
//
// Frames: points in cam0's frame, metres (the rig's baseline unit).

#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "engine/dense/spherical_rectification.h"
#include "engine/features/mirror_mask.h"
#include "engine/geometry/camera_model.h"
#include "engine/geometry/ply.h"
#include "engine/util/progress.h"

namespace omnirig::dense {

struct DenseStereoOptions {
  // The grid: by default 1.25 times the images' finest angular step (bench_dense: on the room
  // renders the same accuracy as the finest step with a 5-cell window, 2/3 of the points, about
  // 0.6 of the CPU; the target is 0.4 s per pair). grid.step_factor 1 (or grid.step_rad) keeps
  // every detail of the images.
  SphericalGridOptions grid{0.0, 1.25};
  // The largest parallax searched (the angle at the point between the two rays). A point at
  // angle theta from the baseline and range r has parallax ~ baseline * sin(theta) / r: 8 degrees
  // reaches 0.7 m for a 0.1 m baseline.
  double max_parallax_deg = 8.0;
  // cv::StereoSGBM: matching window (odd), smoothness P1 = smoothness_p1 w^2 and P2 =
  // smoothness_p2 w^2 (w the window; the penalties of a one-cell and of a larger disparity
  // change between neighbours), uniqueness margin in percent, speckle filter (regions smaller
  // than speckle_window_cells whose disparity varies by at most speckle_range_cells are
  // removed), and the left-right consistency check's largest disagreement in cells. SGBM's
  // cost does not depend on the window (the path aggregation dominates). 9 cells since
  // 2026-12-07 (7 before), chosen with the smoothness below on the development sets (2 pairs
  // each, median / within 1 % of range): 5 cells gave the room 0.331 % / 87.3 % and the noisy
  // room 0.441 % / 80.2 %, 7 cells 0.318 / 88.5 and 0.406 / 83.0, 9 cells 0.311 / 89.2 and
  // 0.387 / 84.4, 11 cells 0.348 / 84.2 and 0.425 / 79.8 with 8 % fewer points.
  int block_size = 9;
  // The smoothness: 32 and 192 since 2026-12-07 (OpenCV's customary 8 and 32 before). Chosen on
  // the development sets alone (bench_dense --development-only --sgbm-p1 --sgbm-p2, 2 pairs
  // each, median error / within 1 % of range): 8/32 gave the room 0.344 % / 86.6 % and the noisy
  // room 0.487 % / 76.3 %; 16/96 0.327 / 87.7 and 0.439 / 80.1; 24/128 0.320 / 88.2 and
  // 0.416 / 81.9; 32/192 0.318 / 88.5 and 0.406 / 83.0; 48/256 0.324 / 88.7 and 0.402 / 83.9.
  // The noise makes SGBM's integer disparities wander between neighbours; the stronger
  // penalties keep the start the refinement steps from within its reach. On the held-out
  // lounge, which did not choose (4 pairs): 0.698 % -> 0.593 % with the 7-cell window, 0.573 %
  // with 9 (docs/dense.md).
  int smoothness_p1 = 32;
  int smoothness_p2 = 192;
  int uniqueness_ratio = 10;
  int speckle_window_cells = 100;
  int speckle_range_cells = 2;
  int left_right_max_diff_cells = 1;
  // Confidence: the zero-mean normalised cross-correlation of the two confidence_window_cells
  // square windows the disparity pairs, with image_noise_grey added to both windows' standard
  // deviation so that textureless windows (whose correlation is noise) score low. Cells below
  // min_confidence are not reported.
  int confidence_window_cells = 7;
  double image_noise_grey = 2.0;
  double min_confidence = 0.5;
  // Sub-cell refinement of SGBM's disparity (RefineDisparity in dense_stereo.cc): one
  // Gauss-Newton step of a 1-D Lucas-Kanade fit along the row over square windows of
  // refine_window_cells (the figures here with 11 cells; 15 since 2026-11-28). SGBM's
  // own sub-pixel disparity is drawn towards whole cells; bench_dense, 2 pairs each, 2026-11-27:
  // on the development room the median error fell from 0.530 % to 0.343 % of range, on the
  // held-out lounge from 0.827 % to 0.801 % (its JPEG and sensor noise dominate), on the same
  // lounge without noise and JPEG from 0.621 % to 0.364 %. Not a job parameter: `false` only
  // lets bench_dense and the tests measure SGBM's own disparity beside it.
  bool refine_subcell = true;
  // The refinement's window (odd). The image noise's share of a window's fit falls with its
  // size, a slanted surface's departure from one disparity per window grows with it.
  // bench_dense, development sets, 2 pairs each (2026-11-28), with the range std calibrated
  // again for each window: 11 cells gave the room 0.343 % / 86.1 % within 1 %, the noisy room
  // 0.501 % / 74.8 %; 15 cells 0.344 % / 86.6 % and 0.487 % / 76.3 % (4 pairs: 0.351 / 86.2 and
  // 0.507 / 74.8 against 0.352 / 85.7 and 0.524 / 73.2); 21 cells 0.373 % on the room. Box
  // sums: the window's size costs nothing.
  int refine_window_cells = 15;
  // Each point's disparity std (cells, 1 sigma), turned into its range std:
  // sqrt(disparity_std_cells^2 + (disparity_std_scale * fit_std)^2), where fit_std is the
  // refinement's least-squares std of the cell (0 without refinement). Calibrated on the two
  // development sets at once (bench_dense --calibrate-std, 2 pairs each, 2026-12-08, the
  // 15-cell window stepping from the window's mean disparity, SGBM's 9-cell window and
  // smoothness 32 / 192): the room as rendered (69.7 % of the points within 1 std of the true
  // range along their ray, 91.1 % within 2) and the room with more sensor noise and JPEG
  // (70.1 %, 91.7 %; stepping from each cell's own disparity it was 0.07 cells and scale 3.2,
  // with SGBM's 7-cell window and smoothness 8 / 32 0.02 cells and scale 5.0, with the 11-cell
  // refinement window 3.6); the errors' tail is heavier than a Gaussian's, so no pair of values
  // reaches 95 % at 2 std without overstating the 1-std share. The fit's std alone
  // underestimates: neighbouring cells of the grid share image pixels (the grid resamples the
  // images), and JPEG and sensor noise are spatially correlated, so the window's samples are
  // not independent. (An estimate of the images' noise from the images themselves did not
  // help: JPEG removes the fine-scale noise such an estimate sees while the disparity error
  // grows; docs/dense.md.)
  double disparity_std_cells = 0.04;
  double disparity_std_scale = 2.6;
  // Points whose range std exceeds this fraction of their range are not reported.
  double max_relative_range_std = 0.1;
  // Mirror mask (engine/features/mirror_mask.h, shape kDarkRowEnds): along each grid row,
  // cells whose 5x5-blurred grey level is at or below dark_level and that connect to either end
  // of the row (beyond the mirror's rim, inside its central hole) are masked, then the mask is
  // eroded by mask_margin_cells.
  double dark_level = 20.0;
  int mask_margin_cells = 4;
  MirrorMaskOptions MaskOptions() const;
  // Pair-level check that the images fit the rig: a shift of one image, or a rig that does not
  // fit, moves every match along the epipolar line too, a disparity offset no per-cell test can
  // see; but it also moves matches across the lines (grid rows) at most azimuths. About
  // epipolar_samples textured cells of cam0 on a lattice are matched in cam1 over the whole
  // disparity range and epipolar_search_rows rows either side (normalised cross-correlation of
  // 11 x 11 windows, kept when above 0.8); when the median distance of the matches from their
  // row exceeds max_epipolar_offset_cells, every cell's confidence is scaled by
  // max_epipolar_offset_cells / offset.
  int epipolar_samples = 720;
  int epipolar_search_rows = 4;
  double max_epipolar_offset_cells = 0.75;

  void Check() const;
};

struct DensePoint {
  Eigen::Vector3f point_in_cam0 = Eigen::Vector3f::Zero();
  std::array<uint8_t, 3> rgb{0, 0, 0};
  float confidence = 0.f;
  float range_std_m = 0.f;
};

// Panoramas are the grid transposed: one column per azimuth (360 degrees), one row per angle
// from the baseline, row 0 being the largest angle (for an upright vertical rig, whose baseline
// points down, row 0 is up).
struct DensePairResult {
  cv::Mat range_m;                 // CV_32F, metres from cam0's centre; 0 where unknown
  cv::Mat range_std_m;             // CV_32F; 0 where unknown
  cv::Mat confidence;              // CV_32F in [0, 1]; 0 where unmatched
  std::vector<DensePoint> points;  // one per known range cell
  int num_mirror_cells = 0;        // cells inside both mirror masks: the ones that could match
  int num_matched_cells = 0;       // disparity found (left-right consistent, not a speckle)
  int num_points = 0;              // confident and certain enough: points.size()
  double mean_confidence = 0.0;    // over the matched cells
  // The pair-level check (DenseStereoOptions::max_epipolar_offset_cells): the median distance
  // of the sample matches from their epipolar line (grid cells; -1 when fewer than 30 samples
  // matched), how many matched, and the factor every confidence was scaled by (1 = fits).
  double epipolar_offset_cells = -1.0;
  int num_epipolar_samples = 0;
  double confidence_scale = 1.0;
  // Wall seconds of each stage (rectification and masks, semi-global matching, the matched
  // windows' correlation, the pair-level check, triangulation and panoramas).
  struct Seconds {
    double rectify = 0.0, match = 0.0, confidence = 0.0, epipolar = 0.0, refine = 0.0,
           triangulate = 0.0;
  } seconds;
};

// Holds the rig's rectification tables (SharedRectifier: built once per rig in the process, and
// with `tables_dir` kept there on disk for later processes); Reconstruct() is const.
class DenseStereo {
 public:
  // Throws InvalidArgument for invalid options or rig.
  DenseStereo(const StereoRig& rig, const DenseStereoOptions& options,
              const std::filesystem::path& tables_dir = {});

  // Images are 8-bit BGR or grey, of the rig's image sizes (throws InvalidArgument otherwise).
  DensePairResult Reconstruct(const cv::Mat& image0, const cv::Mat& image1,
                              const ProgressSink& progress = ProgressSink()) const;

  const SphericalRectifier& rectifier() const { return *rectifier_; }
  int num_disparities() const { return num_disparities_; }

 private:
  // Both cameras' images on the grid and their mirror masks (RectifyPair).
  struct RectifiedPair {
    cv::Mat colour0, grey0, grey1;  // cam0 as given (grey or BGR), both grey
    cv::Mat mask0, mask1;           // MirrorMask of each
  };
  // The panoramas' cells in the grid's layout (transposed at the end of Reconstruct).
  struct GridCells {
    cv::Mat range, range_std, confidence;  // CV_32F, 0 where unknown
  };

  // Rectifies and masks the two cameras at once (one on each of two threads).
  RectifiedPair RectifyPair(const cv::Mat& image0, const cv::Mat& image1) const;

  // Range, its std and the confidence of every matched cell of columns [first, first +
  // disparity.cols), from the disparity (CV_32F cells, not positive where none), its fit's std
  // (CV_32F cells) and the matched windows' correlation over those columns; counts the mirror
  // and matched cells and the mean confidence. Confidences are scaled by
  // result->confidence_scale.
  void TriangulateCells(const cv::Mat& disparity, const cv::Mat& disparity_std,
                        const cv::Mat& correlation, int first, const RectifiedPair& pair,
                        GridCells* cells, DensePairResult* result) const;

  // One DensePoint per known range cell, in row-major grid order (cam0's frame).
  void CollectPoints(const GridCells& cells, const cv::Mat& colour0, DensePairResult* result) const;

  StereoRig rig_;
  DenseStereoOptions options_;
  std::shared_ptr<const SphericalRectifier> rectifier_;  // SharedRectifier: built once per rig
  int num_disparities_ = 0;
  // Per disparity value k / kDisparitySteps cells of parallax p (k in [1, kDisparitySteps
  // num_disparities)): the law of sines as range = baseline (sin(theta0) cot(p) + cos(theta0))
  // and its std per disparity cell baseline sin(theta0) / sin^2(p) * step, so that a cell costs
  // no trigonometry (1/256 cell rounds a range by at most 0.2 % of its std at 1 cell of std).
  static constexpr int kDisparitySteps = 256;
  std::vector<double> cot_parallax_, range_std_per_sin_theta_;
  // Per grid column: sin and cos of the angle from the baseline.
  std::vector<double> sin_theta_, cos_theta_;
};

// The points as a PLY cloud: position, colour, confidence and range_std_m (each point's range
// standard deviation, metres), with `comment` as the header's comment line.
PlyCloud ToPlyCloud(const std::vector<DensePoint>& points, const std::string& comment = "");

// The median distance (grid cells) of cam0's textured cells' best matches in cam1 from their
// grid row, and how many samples matched (see DenseStereoOptions::epipolar_samples); -1 when
// fewer than 30 did. grey0/grey1 are the rectified images, mask0 cam0's mirror mask.
std::pair<double, int> EpipolarOffset(const cv::Mat& grey0, const cv::Mat& grey1,
                                      const cv::Mat& mask0, int num_disparities,
                                      const DenseStereoOptions& options);

// Zero-mean normalised cross-correlation of the window x window neighbourhoods of `a` and `b`
// (CV_32F, same size) at every cell, with noise added to both standard deviations (see
// DenseStereoOptions::image_noise_grey). CV_32F in [-1, 1].
cv::Mat WindowCorrelation(const cv::Mat& a, const cv::Mat& b, int window, double noise_grey);

}  // namespace omnirig::dense
