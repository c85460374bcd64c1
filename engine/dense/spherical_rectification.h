#pragma once
// Epipolar-aligned spherical rectification of a calibrated stereo rig.
//
// Both cameras are resampled onto one grid of directions in a frame whose pole (+z) is the
// baseline direction, from cam0's centre towards cam1's:
//   row r  = the angle around the baseline (azimuth) phi = r * azimuth_step_rad, in [0, 2 pi);
//   col c  = the angle from the baseline theta = theta_max_rad - c * theta_step_rad.
// A scene point, cam0 and cam1 span one plane containing the baseline (the epipolar plane), so it
// has the same phi from both cameras: every epipolar curve is one grid row. Seen from cam1 the
// angle from the baseline is larger (theta1 = theta0 + parallax), so cam1's match of cam0's
// column c lies at column c - d with d = parallax / theta_step_rad >= 0: cam0 is the "left"
// image of OpenCV's stereo matchers and d their disparity.
//
// Lifting and projection are the unified model's (engine/geometry/unified_camera.h, eq. 6 of
// the paper for the lifting); the grid's directions are projected into each camera once per rig
// and stored as cv::remap tables.

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include <Eigen/Core>

#include "engine/geometry/camera_model.h"

namespace omnirig::dense {

struct SphericalGridOptions {
  // Angular step of the grid in both directions; 0 = the images' finest angular resolution
  // (the angle between neighbouring pixels at the mirror's outer edge, where the image is
  // sharpest in angle), so that no detail of the images is lost.
  double step_rad = 0.0;
  // With step_rad 0: the automatic step times this factor (>= 1). A dense map fusing at 2 cm
  // needs less than the images' finest detail (DenseMapOptions::grid_step_factor).
  double step_factor = 1.0;

  void Check() const;
};

// The grid and its remap tables for one rig. Build once per rig; Rectify() is const and
// thread-safe.
class SphericalRectifier {
 public:
  // Throws InvalidArgument for invalid intrinsics, a zero baseline or invalid options.
  SphericalRectifier(const StereoRig& rig, const SphericalGridOptions& options);

  int rows() const { return rows_; }  // azimuth samples over 360 degrees
  int cols() const { return cols_; }  // samples of the angle from the baseline
  double azimuth_step_rad() const { return 2.0 * M_PI / rows_; }
  double theta_step_rad() const { return theta_step_rad_; }
  double theta_max_rad() const { return theta_max_rad_; }
  double baseline_m() const { return baseline_m_; }
  double Theta(double col) const { return theta_max_rad_ - col * theta_step_rad_; }
  double Phi(double row) const { return row * azimuth_step_rad(); }

  // Camera `camera`'s image (0 or 1; any type cv::remap takes) resampled onto the grid
  // (bilinear); cells whose direction does not project into the image are 0.
  cv::Mat Rectify(const cv::Mat& image, int camera) const;

  // 255 where cell's direction projects into camera `camera`'s image, else 0 (CV_8U).
  const cv::Mat& ValidMask(int camera) const { return valid_[camera]; }

  // cam0_from_grid: the rotation taking grid-frame directions into cam0's frame.
  const Eigen::Matrix3d& cam0_from_grid() const { return cam0_from_grid_; }

 private:
  friend std::shared_ptr<const SphericalRectifier> SharedRectifier(const StereoRig&,
                                                                   const SphericalGridOptions&,
                                                                   const std::filesystem::path&);
  SphericalRectifier() = default;
  // The tables file (RectificationTablesFileName): `key` (every number the tables depend on),
  // the grid and the tables. Read() returns null for a missing, truncated or other-version file
  // or another key; Write() writes a temporary file, flushes it to disk and renames it over
  // `path`, so that a reader (another process) sees the old file or the whole new one.
  static std::shared_ptr<const SphericalRectifier> Read(const std::filesystem::path& path,
                                                        const std::vector<double>& key);
  void Write(const std::filesystem::path& path, const std::vector<double>& key) const;

  int rows_ = 0;
  int cols_ = 0;
  double theta_step_rad_ = 0.0;
  double theta_max_rad_ = 0.0;
  double baseline_m_ = 0.0;
  Eigen::Matrix3d cam0_from_grid_;
  // The source pixel of each cell in cv::remap's fixed-point form (CV_16SC2 whole pixels and
  // CV_16UC1 fractions): remap converts float tables into it on every call otherwise.
  cv::Mat map_xy_[2], map_fraction_[2];
  cv::Mat valid_[2];
};

// The rectifier of `rig` with `options`, shared: the last two built in the process are kept
// (keyed by every number of the rig and the options), so that the jobs of one rig (stereo
// pairs, a SLAM job's dense map) build the tables once; they take about as long as one pair's
// reconstruction (bench_dense) and some 40 MB at 1024x768. With `tables_dir` (not empty) the
// tables are also kept on disk, one file per rig and options (RectificationTablesFileName): a
// later process reads them (bench_dense: a few hundredths of a second) instead of building
// them; a file it cannot read or write (a full disk, a read-only folder) only costs the
// building. Thread-safe. Throws as the constructor does.
std::shared_ptr<const SphericalRectifier> SharedRectifier(
    const StereoRig& rig, const SphericalGridOptions& options,
    const std::filesystem::path& tables_dir = {});

// The byte budget of a tables folder: SharedRectifier prunes it to this after each file it
// writes (PruneRectificationTables). About twenty rigs of 1024x768 cameras on the default grid
// (25 MB a file), so that the folder of a service that sees many rigs, or many calibrations of
// one, never grows without limit.
constexpr uintmax_t kRectificationTablesMaxBytes = uintmax_t{512} << 20;

// Removes the least recently used tables files ("rectification-v*.bin", any version) of `dir`
// until the rest fit in `max_bytes`; the most recently used file is always kept. "Used" is the
// file's modification time: SharedRectifier sets it to now whenever it reads a file, so that it
// holds on file systems mounted without access times. Temporary files (".part-") are the
// service's start-up check's. Returns the number of files removed; errors (a file removed by
// another process meanwhile, a folder that cannot be listed) only leave files in place.
int PruneRectificationTables(const std::filesystem::path& dir, uintmax_t max_bytes);

// "rectification-vN-HASH.bin": N the file format's version (a new version is a new file, the
// old ones are never read), HASH 16 hex digits of every number of the rig and the options.
std::string RectificationTablesFileName(const StereoRig& rig, const SphericalGridOptions& options);

// The finest angle between the bearings of neighbouring pixels (radially and tangentially) on
// the largest circle around the principal point that fits in the image; the grid's default step.
double FinestAngularStep(const CameraModel& camera);

}  // namespace omnirig::dense
