#pragma once
// What a calibration tells its user to do next: where on the mirror disk the used corners fall,
// how uncertain the calibrated projection is over the disk, and where views are missing.
//
// The disk: the rim circle found by the single-viewpoint check when it ran, else the largest
// circle around the principal point inside the image. Coverage: the fraction of the disk's area
// within near_px of a used (inlier) corner. Uncertainty: the standard deviation of the projected
// pixel, sqrt(trace(Var)), of a point on each pixel's ray at the median distance of the boards,
// attached to the mean of the board frames (mrcal's "mean frames"): the joint covariance of the
// free intrinsics and the board poses (the Gauss-Newton normal matrix of every used corner's
// reprojection, scaled by the residual variance per coordinate) moves the point with the board
// poses as they follow the intrinsics (and by their own noise). A point fixed in the camera frame
// instead gives a flat map: the weakly observable xi / gamma direction, which the boards' poses
// absorb at the corners, moves it everywhere alike (docs/accuracy.md).
//
// Advice, in plain sentences, at any coverage: the disk is cut into 12 clock sectors (12 o'clock
// up, 3 o'clock right, as the image is shown) and three rings (inner, middle, outer: 0.4 and 0.7
// of the radius); every region whose coverage is below min_sector_coverage is named ("no corner
// in the outer ring, 3 to 5 o'clock"), neighbouring sectors of a ring joined. Until the
// uncertainty map is flat (no region's median above flat_uncertainty_ratio times the disk's), the
// regions where it is highest and the board poses missing from the used views are named too:
// tilted (no view at tilted_deg or more to the line of sight), near (no view at near_ratio of the
// median board distance or nearer), far (none at far_ratio of it or farther). Azimuth is measured
// in the image around the disk's centre, 0 deg along +u (right), 90 deg along +v (down).

#include <filesystem>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "engine/calib/board.h"
#include "engine/calib/calibrate.h"
#include "engine/features/image.h"

namespace omnirig {

struct CoverageOptions {
  double near_px = 30.0;
  int grid_step_px = 4;  // of the coverage and uncertainty grids
  double min_sector_coverage = 0.1;  // of a region's area, below which it has "no corner"
  double flat_uncertainty_ratio = 2.0;
  double tilted_deg = 30.0;
  double near_ratio = 0.6;
  double far_ratio = 1.6;

  void Check() const;
};

struct CoverageReport {
  Eigen::Vector2d disk_centre_px = Eigen::Vector2d::Zero();
  double disk_radius_px = 0.0;
  double covered_fraction = 0.0;  // of the disk's area within near_px of a used corner
  // Predicted projection uncertainty over the disk (px, 1 sigma); max and median over the disk.
  bool uncertainty_valid = false;  // false when the covariance is singular
  double max_uncertainty_px = 0.0;
  double median_uncertainty_px = 0.0;
  // The uncertainty (px) at pixel (col, row) * uncertainty_step_px, 0 outside the disk.
  cv::Mat uncertainty_px;  // CV_32FC1
  int uncertainty_step_px = 0;
  // A region of the disk (ring, clock sectors from_hour to to_hour, to_hour exclusive: 3 to 5
  // o'clock is the sectors 3-4 and 4-5) with no corner, or where the uncertainty is highest.
  struct Region {
    std::string ring;  // "inner", "middle", "outer"
    int from_hour = 12;
    int to_hour = 12;  // equal to from_hour: all around
    double covered_fraction = 0.0;
    double median_uncertainty_px = 0.0;  // 0 when not known
  };
  std::vector<Region> uncovered_regions;
  std::vector<Region> uncertain_regions;  // empty when the uncertainty map is flat
  bool uncertainty_flat = false;
  std::vector<std::string> missing_poses;  // of "tilted", "near", "far"
  double median_board_distance_m = 0.0;
  double max_tilt_deg = 0.0;
  double min_board_distance_m = 0.0;
  double max_board_distance_m = 0.0;
  std::vector<std::string> advice;  // plain sentences, empty when there is nothing to add
  // Images the size of the calibrated camera's: the used corners and the covered area over
  // `background` (or grey); the uncertainty as a colour map with its scale in the caption.
  cv::Mat coverage_image;
  cv::Mat uncertainty_image;
};

// Analyses `report` (a successful calibration of `board`). `background` may be empty or an image
// of the camera's size (drawn under the coverage). `rim_circle_px` (u, v, r) when known.
CoverageReport AnalyseCoverage(const CalibrationReport& report, const BoardSpec& board,
                               const cv::Mat& background, const Eigen::Vector3d* rim_circle_px,
                               const CoverageOptions& options);

// AnalyseCoverage of a calibration of the images in `images_dir`, drawn over its first used
// image (grey when that cannot be read), with the rim the single-viewpoint check found (when
// it ran and found one).
CoverageReport AnalyseCoverageOfImages(const CalibrationReport& report, const BoardSpec& board,
                                       const std::filesystem::path& images_dir,
                                       const CoverageOptions& options);
// As above, the images read through `read`.
CoverageReport AnalyseCoverageOfImages(const CalibrationReport& report, const BoardSpec& board,
                                       const ImageReader& read, const CoverageOptions& options);

// Writes coverage.coverage_image as `coverage_png` and, when the uncertainty is valid,
// coverage.uncertainty_image as `uncertainty_png` (creating their folders).
void WriteCoverageImages(const CoverageReport& coverage, const std::filesystem::path& coverage_png,
                         const std::filesystem::path& uncertainty_png);

}  // namespace omnirig
