// The spherical grid: epipolar curves are grid rows, and the remap tables are the unified
// model's projection.

#include "engine/dense/spherical_rectification.h"

#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

#include <gtest/gtest.h>

#include "engine/geometry/unified_camera.h"
#include "engine/synth/presets.h"
#include "engine/util/check.h"

namespace omnirig::dense {
namespace {

StereoRig DefaultRig() {
  StereoRig rig;
  rig.cam0 = synth::DefaultCamera().model;
  rig.cam1 = synth::DefaultSecondCamera().model;
  rig.cam0_from_cam1 = synth::DefaultCam0FromCam1();
  return rig;
}

// Unit direction of grid cell (row, col) (fractional allowed) in cam0's frame.
Eigen::Vector3d BearingInCam0(const SphericalRectifier& rectifier, double row, double col) {
  const double theta = rectifier.Theta(col), phi = rectifier.Phi(row);
  return rectifier.cam0_from_grid() * Eigen::Vector3d(std::sin(theta) * std::cos(phi),
                                                      std::sin(theta) * std::sin(phi),
                                                      std::cos(theta));
}

// The grid cell of a direction in cam0's frame (inverse of BearingInCam0): (row, col).
Eigen::Vector2d CellOfBearingInCam0(const SphericalRectifier& rectifier,
                                    const Eigen::Vector3d& bearing) {
  const Eigen::Vector3d in_grid = rectifier.cam0_from_grid().transpose() * bearing.normalized();
  double phi = std::atan2(in_grid.y(), in_grid.x());
  if (phi < 0.0) phi += 2.0 * M_PI;
  const double theta = std::acos(std::clamp(in_grid.z(), -1.0, 1.0));
  return Eigen::Vector2d(phi / rectifier.azimuth_step_rad(),
                         (rectifier.theta_max_rad() - theta) / rectifier.theta_step_rad());
}

// The grid cell of a point seen from cam1's centre, in the grid's (cam0-aligned) frame.
Eigen::Vector2d CellFromCam1(const SphericalRectifier& rectifier, const StereoRig& rig,
                             const Eigen::Vector3d& point_in_cam0) {
  return CellOfBearingInCam0(rectifier, point_in_cam0 - rig.cam0_from_cam1.translation);
}

TEST(SphericalRectification, EveryEpipolarCurveIsOneRow) {
  const StereoRig rig = DefaultRig();
  const SphericalRectifier rectifier(rig, SphericalGridOptions());
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> unit(-1.0, 1.0), range(0.5, 8.0);
  for (int k = 0; k < 1000; ++k) {
    const Eigen::Vector3d point = range(rng) * Eigen::Vector3d(unit(rng), unit(rng), unit(rng)).normalized();
    const Eigen::Vector2d cell0 = CellOfBearingInCam0(rectifier, point);
    const Eigen::Vector2d cell1 = CellFromCam1(rectifier, rig, point);
    double row_difference = std::abs(cell0.x() - cell1.x());
    row_difference = std::min(row_difference, rectifier.rows() - row_difference);  // the seam
    // Near the poles the azimuth is ill-defined; elsewhere the rows agree to rounding.
    const double theta0 = rectifier.Theta(cell0.y());
    if (std::sin(theta0) > 0.05) {
      EXPECT_LT(row_difference, 1e-6) << point.transpose();
    }
    // cam1's match lies to the left (smaller column) by the parallax in cells.
    const double parallax = std::acos(point.normalized().dot(
        (point - rig.cam0_from_cam1.translation).normalized()));
    EXPECT_NEAR(cell0.y() - cell1.y(), parallax / rectifier.theta_step_rad(), 1e-6);
    // BearingInCam0 inverts CellOfBearingInCam0.
    EXPECT_LT((BearingInCam0(rectifier, cell0.x(), cell0.y()) - point.normalized()).norm(), 1e-9);
  }
}

TEST(SphericalRectification, GridCoversTheImagesAtTheirFinestResolution) {
  const StereoRig rig = DefaultRig();
  const SphericalRectifier rectifier(rig, SphericalGridOptions());
  const double finest = std::min(FinestAngularStep(rig.cam0), FinestAngularStep(rig.cam1));
  EXPECT_DOUBLE_EQ(rectifier.theta_step_rad(), finest);
  // About 1 / 380 rad at the edge of a 1024x768 image's inscribed circle (radius ~380 px).
  EXPECT_GT(finest, 1.0 / 600.0);
  EXPECT_LT(finest, 1.0 / 300.0);
  EXPECT_NEAR(rectifier.rows() * rectifier.azimuth_step_rad(), 2.0 * M_PI, 1e-12);
  // The band reaches from the baseline (the hole) to beyond the horizon (the rim is ~20 degrees
  // above it for DefaultCamera).
  EXPECT_GT(rectifier.theta_max_rad(), 100.0 * M_PI / 180.0);
  SphericalGridOptions coarse;
  coarse.step_rad = 2.0 * finest;
  const SphericalRectifier half(rig, coarse);
  EXPECT_NEAR(half.rows(), rectifier.rows() / 2.0, 1.0);
  coarse.step_rad = -1.0;
  EXPECT_THROW(SphericalRectifier(rig, coarse), InvalidArgument);
}

TEST(SphericalRectification, SharedRectifierBuildsOncePerRigAndKeepsTwo) {
  const StereoRig rig = DefaultRig();
  SphericalGridOptions coarse;
  coarse.step_rad = 0.01;  // small tables: the test is about the cache
  const auto first = SharedRectifier(rig, coarse);
  EXPECT_EQ(SharedRectifier(rig, coarse), first);  // the same tables, not a copy
  EXPECT_EQ(first->theta_step_rad(), 0.01);
  StereoRig moved = rig;
  moved.cam0_from_cam1.translation.z() += 0.01;
  const auto other_rig = SharedRectifier(moved, coarse);
  EXPECT_NE(other_rig, first);
  EXPECT_NEAR(other_rig->baseline_m(), first->baseline_m() + 0.01, 1e-12);
  SphericalGridOptions finer = coarse;
  finer.step_rad = 0.008;
  const auto other_step = SharedRectifier(rig, finer);  // a third entry: `first` is dropped
  EXPECT_NE(other_step, first);
  EXPECT_EQ(SharedRectifier(moved, coarse), other_rig);
  EXPECT_NE(SharedRectifier(rig, coarse), first);  // built again, held by `first` still
  coarse.step_rad = -1.0;
  EXPECT_THROW(SharedRectifier(rig, coarse), InvalidArgument);
}

// The inode of `path` (a rename over it gives it a new one), 0 when it is missing.
ino_t Inode(const std::filesystem::path& path) {
  struct stat info {};
  return ::stat(path.c_str(), &info) == 0 ? info.st_ino : 0;
}

// Drops every table of the process-wide cache (it keeps two): the next call reads the file.
void EvictSharedRectifiers(const StereoRig& rig) {
  for (double step : {0.031, 0.032}) {
    SphericalGridOptions other;
    other.step_rad = step;
    SharedRectifier(rig, other);
  }
}

TEST(SphericalRectification, TablesAreKeptOnDiskAndReadByALaterProcess) {
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) /
                                    ("omnirig_rectification_tables_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  const StereoRig rig = DefaultRig();
  SphericalGridOptions options;
  options.step_rad = 0.009;
  const std::filesystem::path file = dir / RectificationTablesFileName(rig, options);
  EXPECT_EQ(file.filename().string().rfind("rectification-v1-", 0), 0u) << file;
  const auto built = SharedRectifier(rig, options, dir);
  ASSERT_TRUE(std::filesystem::exists(file));
  const ino_t written = Inode(file);

  // Another process (here: the process-wide cache emptied) reads the same tables, not builds them
  // (building writes a new file over the old one).
  EvictSharedRectifiers(rig);
  const auto read = SharedRectifier(rig, options, dir);
  EXPECT_NE(read, built);
  EXPECT_EQ(Inode(file), written);
  EXPECT_EQ(read->rows(), built->rows());
  EXPECT_EQ(read->cols(), built->cols());
  EXPECT_EQ(read->theta_step_rad(), built->theta_step_rad());
  EXPECT_EQ(read->theta_max_rad(), built->theta_max_rad());
  EXPECT_EQ(read->baseline_m(), built->baseline_m());
  EXPECT_TRUE(read->cam0_from_grid() == built->cam0_from_grid());
  cv::Mat image(rig.cam0.height, rig.cam0.width, CV_8U);
  cv::randu(image, 0, 256);
  for (int camera = 0; camera < 2; ++camera) {
    EXPECT_EQ(cv::norm(read->Rectify(image, camera), built->Rectify(image, camera), cv::NORM_INF),
              0.0);
    EXPECT_EQ(cv::norm(read->ValidMask(camera), built->ValidMask(camera), cv::NORM_INF), 0.0);
  }

  // Another rig or grid has its own file.
  StereoRig moved = rig;
  moved.cam0_from_cam1.translation.z() += 0.001;
  EXPECT_NE(RectificationTablesFileName(moved, options), file.filename().string());

  // A torn file (a crash mid-write on a file system without ordered writes) is built again and
  // replaced, as is a file holding another rig's tables under this name.
  const auto size = std::filesystem::file_size(file);
  std::filesystem::resize_file(file, size / 2);
  EvictSharedRectifiers(rig);
  const auto rebuilt = SharedRectifier(rig, options, dir);
  EXPECT_EQ(rebuilt->rows(), built->rows());
  EXPECT_EQ(std::filesystem::file_size(file), size);
  const std::filesystem::path moved_file = dir / RectificationTablesFileName(moved, options);
  SharedRectifier(moved, options, dir);
  std::filesystem::copy_file(moved_file, file, std::filesystem::copy_options::overwrite_existing);
  EvictSharedRectifiers(rig);
  EXPECT_NEAR(SharedRectifier(rig, options, dir)->baseline_m(), built->baseline_m(), 1e-15);

  // A folder it cannot write to only costs the building.
  const std::filesystem::path not_a_folder = dir / "plain_file";
  std::ofstream(not_a_folder) << "x";
  EvictSharedRectifiers(rig);
  EXPECT_EQ(SharedRectifier(rig, options, not_a_folder)->rows(), built->rows());
  std::filesystem::remove_all(dir);
}

TEST(SphericalRectification, TablesFolderIsPrunedToItsBudgetLeastRecentlyUsedFirst) {
  const std::filesystem::path dir = std::filesystem::path(::testing::TempDir()) /
                                    ("omnirig_rectification_prune_" + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  const StereoRig rig = DefaultRig();
  SphericalGridOptions options;
  options.step_rad = 0.02;  // small tables: the test is about the folder
  std::vector<std::filesystem::path> files;
  for (int i = 0; i < 3; ++i) {
    StereoRig other = rig;
    other.cam0_from_cam1.translation.z() += 0.001 * i;
    SharedRectifier(other, options, dir);
    files.push_back(dir / RectificationTablesFileName(other, options));
    ASSERT_TRUE(std::filesystem::exists(files.back()));
  }
  const uintmax_t bytes = std::filesystem::file_size(files[0]);
  // Used in the order 1, 0, 2 (oldest first); a file that is not tables stays whatever its age.
  const auto now = std::filesystem::file_time_type::clock::now();
  std::filesystem::last_write_time(files[1], now - std::chrono::hours(3));
  std::filesystem::last_write_time(files[0], now - std::chrono::hours(2));
  std::filesystem::last_write_time(files[2], now - std::chrono::hours(1));
  std::ofstream(dir / "notes.txt") << "x";
  std::filesystem::last_write_time(dir / "notes.txt", now - std::chrono::hours(9));

  EXPECT_EQ(PruneRectificationTables(dir, 3 * bytes), 0);  // within the budget: nothing goes
  EXPECT_EQ(PruneRectificationTables(dir, 2 * bytes), 1);
  EXPECT_FALSE(std::filesystem::exists(files[1]));  // the least recently used
  EXPECT_TRUE(std::filesystem::exists(files[0]));
  EXPECT_TRUE(std::filesystem::exists(files[2]));
  EXPECT_TRUE(std::filesystem::exists(dir / "notes.txt"));

  // Reading a file is a use: after file 0 is read by a later process (the process-wide cache
  // emptied), file 2 is the least recently used.
  EvictSharedRectifiers(rig);
  SharedRectifier(rig, options, dir);
  EXPECT_GT(std::filesystem::last_write_time(files[0]),
            std::filesystem::last_write_time(files[2]));
  EXPECT_EQ(PruneRectificationTables(dir, bytes), 1);
  EXPECT_TRUE(std::filesystem::exists(files[0]));
  EXPECT_FALSE(std::filesystem::exists(files[2]));
  // The most recently used file stays even when it alone exceeds the budget.
  EXPECT_EQ(PruneRectificationTables(dir, 0), 0);
  EXPECT_TRUE(std::filesystem::exists(files[0]));
  EXPECT_EQ(PruneRectificationTables(dir / "missing", 0), 0);
  std::filesystem::remove_all(dir);
}

TEST(SphericalRectification, RemapTablesAreTheModelsProjection) {
  const StereoRig rig = DefaultRig();
  const SphericalRectifier rectifier(rig, SphericalGridOptions());
  // An image whose grey level encodes u + 2 v is resampled exactly (it is linear) where the
  // direction projects inside the image.
  cv::Mat ramp(rig.cam1.height, rig.cam1.width, CV_32F);
  for (int v = 0; v < ramp.rows; ++v)
    for (int u = 0; u < ramp.cols; ++u) ramp.at<float>(v, u) = static_cast<float>(u + 2 * v);
  const cv::Mat on_grid = rectifier.Rectify(ramp, 1);
  const Eigen::Matrix3d cam1_from_cam0 = rig.cam0_from_cam1.rotation.conjugate().toRotationMatrix();
  int checked = 0;
  for (int r = 0; r < rectifier.rows(); r += 37) {
    for (int c = 0; c < rectifier.cols(); c += 11) {
      if (!rectifier.ValidMask(1).at<uint8_t>(r, c)) continue;
      const auto pixel =
          Project(rig.cam1.intrinsics, cam1_from_cam0 * BearingInCam0(rectifier, r, c));
      ASSERT_TRUE(pixel.has_value());
      if (pixel->x() > ramp.cols - 2.0 || pixel->y() > ramp.rows - 2.0) continue;
      // cv::remap quantises the source position to 1/32 px: u + 2 v is off by up to 3/64.
      EXPECT_NEAR(on_grid.at<float>(r, c), pixel->x() + 2.0 * pixel->y(), 3.0 / 64 + 1e-3);
      ++checked;
    }
  }
  EXPECT_GT(checked, 1000);
}

}  // namespace
}  // namespace omnirig::dense
