#include "engine/calib/coverage.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <optional>
#include <sstream>

#include <Eigen/Dense>
#include <Eigen/Geometry>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "engine/geometry/rigid3.h"
#include "engine/features/image.h"
#include "engine/geometry/unified_camera.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {
namespace {

using Matrix2X = Eigen::Matrix<double, 2, Eigen::Dynamic>;

// d pixel / d intrinsics[free] at point_in_cam by central differences; false when a perturbed
// point does not project.
bool IntrinsicsJacobian(const UnifiedIntrinsics& intrinsics, const std::vector<int>& free,
                        const Eigen::Vector3d& point_in_cam, Matrix2X* jacobian) {
  jacobian->resize(2, static_cast<int>(free.size()));
  for (size_t j = 0; j < free.size(); ++j) {
    UnifiedIntrinsics plus = intrinsics, minus = intrinsics;
    const double step = 1e-6 * std::max(1.0, std::abs(intrinsics.params[free[j]]));
    plus.params[free[j]] += step;
    minus.params[free[j]] -= step;
    const auto a = Project(plus, point_in_cam), b = Project(minus, point_in_cam);
    if (!a || !b) return false;
    jacobian->col(static_cast<int>(j)) = (*a - *b) / (2.0 * step);
  }
  return true;
}

// d pixel / d (rotation increment, translation increment) of the board point `x` at
// cam_from_board, the increments applied on the camera side.
bool PoseJacobian(const UnifiedIntrinsics& intrinsics, const Rigid3d& cam_from_board,
                  const Eigen::Vector3d& x, Eigen::Matrix<double, 2, 6>* jacobian) {
  const Eigen::Vector3d point = cam_from_board * x;
  for (int k = 0; k < 6; ++k) {
    const double step = 1e-7;
    Eigen::Vector3d plus = point, minus = point;
    if (k < 3) {
      const Eigen::Vector3d axis = Eigen::Vector3d::Unit(k);
      plus = Eigen::AngleAxisd(step, axis) * (point - cam_from_board.translation) +
             cam_from_board.translation;
      minus = Eigen::AngleAxisd(-step, axis) * (point - cam_from_board.translation) +
              cam_from_board.translation;
    } else {
      plus[k - 3] += step;
      minus[k - 3] -= step;
    }
    const auto a = Project(intrinsics, plus), b = Project(intrinsics, minus);
    if (!a || !b) return false;
    jacobian->col(k) = (*a - *b) / (2.0 * step);
  }
  return true;
}

// What the covariance of a calibration says about one used view's board pose: how it follows a
// change of the intrinsics (the Gauss-Newton response -D^-1 B^T dk, the increments of
// PoseJacobian) and its own covariance given the intrinsics (variance * D^-1).
struct ViewPoseBlocks {
  Eigen::Matrix<double, 6, Eigen::Dynamic> response;
  Eigen::Matrix<double, 6, 6> covariance;
  Eigen::Vector3d translation;
};

struct CalibrationCovariance {
  Eigen::MatrixXd intrinsics;  // of the free intrinsics, board poses eliminated
  std::vector<ViewPoseBlocks> views;
  double median_board_distance_m = 0.0;
};

// One used view's blocks of the Gauss-Newton normal matrix over its inlier corners: the
// intrinsics' (a), the intrinsics' and the pose's (b), the pose's (d).
struct ViewNormalBlocks {
  Eigen::MatrixXd a;
  Eigen::MatrixXd b;
  Eigen::Matrix<double, 6, 6> d = Eigen::Matrix<double, 6, 6>::Zero();
};

// The normal blocks of one view; adds its corners' squared residuals and coordinates to the
// totals.
ViewNormalBlocks ViewNormal(const UnifiedIntrinsics& intrinsics, const std::vector<int>& free,
                            const std::vector<Eigen::Vector3d>& object_points,
                            const CalibrationImageReport& image, double* squared_error,
                            int* num_coordinates) {
  const int m = static_cast<int>(free.size());
  ViewNormalBlocks blocks;
  blocks.a = Eigen::MatrixXd::Zero(m, m);
  blocks.b = Eigen::MatrixXd::Zero(m, 6);
  for (size_t i = 0; i < image.corner_ids.size(); ++i) {
    if (i < image.inlier.size() && !image.inlier[i]) continue;
    const Eigen::Vector3d& x = object_points[image.corner_ids[i]];
    Matrix2X ji;
    Eigen::Matrix<double, 2, 6> pi;
    if (!IntrinsicsJacobian(intrinsics, free, image.cam_from_board * x, &ji) ||
        !PoseJacobian(intrinsics, image.cam_from_board, x, &pi)) {
      continue;
    }
    blocks.a += ji.transpose() * ji;
    blocks.b += ji.transpose() * pi;
    blocks.d += pi.transpose() * pi;
    if (i < image.reprojected_px.size()) {
      *squared_error += (image.reprojected_px[i] - image.corners_px[i]).squaredNorm();
    }
    *num_coordinates += 2;
  }
  return blocks;
}

// The covariance of a calibration's free intrinsics and board poses (see coverage.h) from the
// Gauss-Newton normal matrix of every used inlier corner, scaled by the residual variance per
// coordinate; false when singular.
bool EstimateCovariance(const CalibrationReport& report, const BoardSpec& board,
                        const std::vector<int>& free, CalibrationCovariance* covariance) {
  const int m = static_cast<int>(free.size());
  const std::vector<Eigen::Vector3d> object_points = board.ObjectPoints();
  Eigen::Vector3d board_centre = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& x : object_points) board_centre += x / object_points.size();
  // The board poses eliminated view by view (Schur complement).
  Eigen::MatrixXd normal = Eigen::MatrixXd::Zero(m, m);
  double squared_error = 0.0;
  int num_coordinates = 0;
  std::vector<double> distances;
  covariance->views.clear();
  for (const CalibrationImageReport& image : report.images) {
    if (!image.used) continue;
    const ViewNormalBlocks blocks = ViewNormal(report.camera.intrinsics, free, object_points, image,
                                               &squared_error, &num_coordinates);
    const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> d_ldlt(blocks.d);
    if (d_ldlt.info() != Eigen::Success || !(blocks.d.determinant() > 0.0)) continue;
    normal += blocks.a - blocks.b * d_ldlt.solve(blocks.b.transpose());
    ViewPoseBlocks view;
    view.response = -d_ldlt.solve(blocks.b.transpose());
    view.covariance = d_ldlt.solve(Eigen::Matrix<double, 6, 6>::Identity());
    view.translation = image.cam_from_board.translation;
    covariance->views.push_back(view);
    distances.push_back((image.cam_from_board * board_centre).norm());
  }
  const int num_views = static_cast<int>(covariance->views.size());
  const int dof = num_coordinates - m - 6 * num_views;
  if (dof <= 0) return false;
  const double variance = squared_error / dof;
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(normal);
  if (eigen.info() != Eigen::Success || !(eigen.eigenvalues().minCoeff() > 1e-12 *
                                          eigen.eigenvalues().maxCoeff())) {
    return false;
  }
  covariance->intrinsics = variance * eigen.eigenvectors() *
                           eigen.eigenvalues().cwiseInverse().asDiagonal() *
                           eigen.eigenvectors().transpose();
  for (ViewPoseBlocks& view : covariance->views) view.covariance *= variance;
  std::nth_element(distances.begin(), distances.begin() + distances.size() / 2, distances.end());
  covariance->median_board_distance_m = distances[distances.size() / 2];
  return true;
}

std::string SectorAdvice(double from_deg, double to_deg, bool rim) {
  std::ostringstream os;
  os << "no board seen between azimuth " << from_deg << " and " << to_deg << " deg "
     << (rim ? "near the rim" : "in the inner half of the disk")
     << ": add views with the board there";
  return os.str();
}

// The coverage map, its fraction and the sector advice.
cv::Mat Coverage(const CalibrationReport& report, const CoverageOptions& options,
                 CoverageReport* coverage) {
  const int width = report.camera.width, height = report.camera.height;
  cv::Mat seeds(height, width, CV_8UC1, cv::Scalar(255));
  for (const CalibrationImageReport& image : report.images) {
    if (!image.used) continue;
    for (size_t i = 0; i < image.corners_px.size(); ++i) {
      if (i < image.inlier.size() && !image.inlier[i]) continue;
      const int u = static_cast<int>(std::lround(image.corners_px[i].x()));
      const int v = static_cast<int>(std::lround(image.corners_px[i].y()));
      if (u >= 0 && v >= 0 && u < width && v < height) seeds.at<uint8_t>(v, u) = 0;
    }
  }
  cv::Mat distance;
  cv::distanceTransform(seeds, distance, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  const int num_sectors = static_cast<int>(std::ceil(360.0 / options.azimuth_sector_deg));
  std::vector<std::array<int, 2>> in_sector(num_sectors, {0, 0}), covered_sector(num_sectors, {0, 0});
  const Eigen::Vector2d& c = coverage->disk_centre_px;
  const double radius = coverage->disk_radius_px;
  int in_disk = 0, covered = 0;
  for (int v = 0; v < height; v += options.grid_step_px) {
    for (int u = 0; u < width; u += options.grid_step_px) {
      const Eigen::Vector2d offset(u - c.x(), v - c.y());
      const double r = offset.norm();
      if (r > radius) continue;
      double azimuth = std::atan2(offset.y(), offset.x()) * 180.0 / M_PI;
      if (azimuth < 0.0) azimuth += 360.0;
      const int sector = std::min(num_sectors - 1,
                                  static_cast<int>(azimuth / options.azimuth_sector_deg));
      const int band = r > 0.5 * radius ? 1 : 0;
      const bool near = distance.at<float>(v, u) <= options.near_px;
      ++in_disk;
      covered += near;
      ++in_sector[sector][band];
      covered_sector[sector][band] += near;
    }
  }
  coverage->covered_fraction = in_disk > 0 ? static_cast<double>(covered) / in_disk : 0.0;
  for (int band : {1, 0}) {
    for (int sector = 0; sector < num_sectors; ++sector) {
      const int n = in_sector[sector][band];
      if (n == 0 || covered_sector[sector][band] >= options.min_sector_coverage * n) continue;
      coverage->advice.push_back(SectorAdvice(
          sector * options.azimuth_sector_deg,
          std::min(360.0, (sector + 1) * options.azimuth_sector_deg), band == 1));
    }
  }
  return distance;
}

cv::Mat DrawCoverage(const cv::Mat& background, const cv::Mat& distance,
                     const CalibrationReport& report, const CoverageOptions& options,
                     const CoverageReport& coverage) {
  const int width = report.camera.width, height = report.camera.height;
  cv::Mat image;
  if (!background.empty() && background.cols == width && background.rows == height) {
    if (background.channels() == 1) {
      cv::cvtColor(background, image, cv::COLOR_GRAY2BGR);
    } else {
      image = background.clone();
    }
    image.convertTo(image, CV_8UC3, 0.6);
  } else {
    image = cv::Mat(height, width, CV_8UC3, cv::Scalar(60, 60, 60));
  }
  cv::Mat disk(height, width, CV_8UC1, cv::Scalar(0));
  const cv::Point centre(static_cast<int>(std::lround(coverage.disk_centre_px.x())),
                         static_cast<int>(std::lround(coverage.disk_centre_px.y())));
  cv::circle(disk, centre, static_cast<int>(coverage.disk_radius_px), cv::Scalar(255), -1);
  cv::Mat near = (distance <= options.near_px) & disk;
  cv::Mat far = (distance > options.near_px) & disk;
  image.setTo(cv::Scalar(40, 160, 40), near);
  cv::Mat tint = image.clone();
  tint.setTo(cv::Scalar(40, 40, 200), far);
  cv::addWeighted(image, 0.6, tint, 0.4, 0.0, image);
  for (const CalibrationImageReport& view : report.images) {
    if (!view.used) continue;
    for (const Eigen::Vector2d& corner : view.corners_px) {
      cv::circle(image, cv::Point2d(corner.x(), corner.y()), 2, cv::Scalar(255, 255, 255), -1);
    }
  }
  cv::circle(image, centre, static_cast<int>(coverage.disk_radius_px), cv::Scalar(255, 255, 0), 1);
  std::ostringstream caption;
  caption.precision(3);
  caption << "within " << options.near_px << " px of a corner: " << 100.0 * coverage.covered_fraction
          << "% of the disk";
  cv::putText(image, caption.str(), cv::Point(8, 20), cv::FONT_HERSHEY_SIMPLEX, 0.5,
              cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  return image;
}

// The standard deviation (px) of the projection of `point` (camera frame) under `covariance`:
// the point is fixed to the mean of the board frames (mrcal's "mean frames"), so it moves with
// the board poses as they follow the intrinsics. A perturbation (dk, dp_i) moves the pixel by
// J_k dk + J_x (1/N) sum_i G_i dp_i, with G_i = [-[point - t_i]x, I] the point's motion under
// board i's pose increment and dp_i = response_i dk + e_i (e_i independent, covariance_i).
// `moved_by_intrinsics` = sum_i G_i response_i at this point.
std::optional<double> ProjectionSigma(const UnifiedIntrinsics& intrinsics,
                                      const std::vector<int>& free,
                                      const CalibrationCovariance& covariance,
                                      const Eigen::Vector3d& point,
                                      const Eigen::MatrixXd& moved_by_intrinsics) {
  Matrix2X j_k;
  if (!IntrinsicsJacobian(intrinsics, free, point, &j_k)) return std::nullopt;
  Eigen::Matrix<double, 2, 3> j_x;
  for (int k = 0; k < 3; ++k) {
    const double step = 1e-6 * std::max(1e-3, point.norm());
    Eigen::Vector3d plus = point, minus = point;
    plus[k] += step;
    minus[k] -= step;
    const auto a = Project(intrinsics, plus), b = Project(intrinsics, minus);
    if (!a || !b) return std::nullopt;
    j_x.col(k) = (*a - *b) / (2.0 * step);
  }
  const double n = static_cast<double>(covariance.views.size());
  const Matrix2X effective = j_k + j_x * moved_by_intrinsics / n;
  Eigen::Matrix3d frames = Eigen::Matrix3d::Zero();
  for (const ViewPoseBlocks& view : covariance.views) {
    Eigen::Matrix<double, 3, 6> g;
    g << -Skew(point - view.translation), Eigen::Matrix3d::Identity();
    frames += g * view.covariance * g.transpose();
  }
  const Eigen::Matrix2d variance = effective * covariance.intrinsics * effective.transpose() +
                                   j_x * frames * j_x.transpose() / (n * n);
  return std::sqrt(std::max(0.0, variance.trace()));
}

// The uncertainty map (px) on the grid, 0 outside the disk; fills max and median. Each grid
// pixel's ray carries a point at the median distance of the boards from the camera.
cv::Mat Uncertainty(const CalibrationReport& report, const BoardSpec& board,
                    const CoverageOptions& options, CoverageReport* coverage) {
  std::vector<int> free;
  for (int i = 0; i < UnifiedIntrinsics::kNumParams; ++i) {
    if (report.intrinsics_std[i] > 0.0) free.push_back(i);
  }
  CalibrationCovariance covariance;
  if (free.empty() || !EstimateCovariance(report, board, free, &covariance)) return cv::Mat();
  // sum_i G_i response_i = -[point]x W + V, linear in the point.
  const int m = static_cast<int>(free.size());
  Eigen::MatrixXd w = Eigen::MatrixXd::Zero(3, m), v = Eigen::MatrixXd::Zero(3, m);
  for (const ViewPoseBlocks& view : covariance.views) {
    w += view.response.topRows<3>();
    v += Skew(view.translation) * view.response.topRows<3>() + view.response.bottomRows<3>();
  }
  const int step = std::max(options.grid_step_px, 8);
  const int width = report.camera.width, height = report.camera.height;
  const UnifiedIntrinsics& intrinsics = report.camera.intrinsics;
  cv::Mat sigma((height + step - 1) / step, (width + step - 1) / step, CV_32FC1, cv::Scalar(0));
  std::vector<double> values;
  for (int row = 0; row < sigma.rows; ++row) {
    for (int col = 0; col < sigma.cols; ++col) {
      const Eigen::Vector2d pixel(col * step, row * step);
      if ((pixel - coverage->disk_centre_px).norm() > coverage->disk_radius_px) continue;
      const auto bearing = Lift(intrinsics, pixel);
      if (!bearing) continue;
      const Eigen::Vector3d point = covariance.median_board_distance_m * bearing->normalized();
      const auto value =
          ProjectionSigma(intrinsics, free, covariance, point, -Skew(point) * w + v);
      if (!value) continue;
      sigma.at<float>(row, col) = static_cast<float>(*value);
      values.push_back(*value);
    }
  }
  if (values.empty()) return cv::Mat();
  std::sort(values.begin(), values.end());
  coverage->uncertainty_valid = true;
  coverage->uncertainty_px = sigma;
  coverage->uncertainty_step_px = step;
  coverage->max_uncertainty_px = values.back();
  coverage->median_uncertainty_px = values[values.size() / 2];
  return sigma;
}

cv::Mat DrawUncertainty(const cv::Mat& sigma, const CalibrationReport& report,
                        const CoverageReport& coverage) {
  const int width = report.camera.width, height = report.camera.height;
  cv::Mat scaled;
  sigma.convertTo(scaled, CV_8UC1, 255.0 / std::max(1e-9, coverage.max_uncertainty_px));
  cv::Mat full;
  cv::resize(scaled, full, cv::Size(width, height), 0, 0, cv::INTER_LINEAR);
  cv::Mat image;
  cv::applyColorMap(full, image, cv::COLORMAP_JET);
  cv::Mat outside(height, width, CV_8UC1, cv::Scalar(255));
  cv::circle(outside,
             cv::Point(static_cast<int>(std::lround(coverage.disk_centre_px.x())),
                       static_cast<int>(std::lround(coverage.disk_centre_px.y()))),
             static_cast<int>(coverage.disk_radius_px), cv::Scalar(0), -1);
  image.setTo(cv::Scalar(0, 0, 0), outside);
  std::ostringstream caption;
  caption.precision(3);
  caption << "projection uncertainty (1 sigma): blue 0, red " << coverage.max_uncertainty_px
          << " px";
  cv::putText(image, caption.str(), cv::Point(8, 20), cv::FONT_HERSHEY_SIMPLEX, 0.5,
              cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  return image;
}

}  // namespace

void CoverageOptions::Check() const {
  OMNIRIG_CHECK_POSITIVE(near_px);
  OMNIRIG_CHECK_AT_LEAST(grid_step_px, 1);
  OMNIRIG_CHECK_IN(azimuth_sector_deg, '(', 0, 360, ']');
  OMNIRIG_CHECK_IN(min_sector_coverage, '[', 0, 1, ']');
}

CoverageReport AnalyseCoverage(const CalibrationReport& report, const BoardSpec& board,
                               const cv::Mat& background, const Eigen::Vector3d* rim_circle_px,
                               const CoverageOptions& options) {
  options.Check();
  OMNIRIG_CHECK(report.camera.width > 0 && report.camera.height > 0,
                "coverage: the calibration has no image size");
  CoverageReport coverage;
  const UnifiedIntrinsics& k = report.camera.intrinsics;
  if (rim_circle_px) {
    coverage.disk_centre_px = rim_circle_px->head<2>();
    coverage.disk_radius_px = rim_circle_px->z();
  } else {
    coverage.disk_centre_px = Eigen::Vector2d(k.u0(), k.v0());
    coverage.disk_radius_px =
        std::max(1.0, std::min({k.u0(), k.v0(), report.camera.width - 1 - k.u0(),
                                report.camera.height - 1 - k.v0()}));
  }
  const cv::Mat distance = Coverage(report, options, &coverage);
  coverage.coverage_image = DrawCoverage(background, distance, report, options, coverage);
  const cv::Mat sigma = Uncertainty(report, board, options, &coverage);
  if (!sigma.empty()) coverage.uncertainty_image = DrawUncertainty(sigma, report, coverage);
  return coverage;
}

CoverageReport AnalyseCoverageOfImages(const CalibrationReport& report, const BoardSpec& board,
                                       const std::filesystem::path& images_dir,
                                       const CoverageOptions& options) {
  return AnalyseCoverageOfImages(report, board, FolderImageReader(images_dir), options);
}

CoverageReport AnalyseCoverageOfImages(const CalibrationReport& report, const BoardSpec& board,
                                       const ImageReader& read, const CoverageOptions& options) {
  cv::Mat background;
  for (const CalibrationImageReport& image : report.images) {
    if (!image.used) continue;
    background = read(image.name, cv::IMREAD_COLOR);
    break;
  }
  const Eigen::Vector3d* rim =
      report.svp && report.svp->found_circle_px ? &*report.svp->found_circle_px : nullptr;
  return AnalyseCoverage(report, board, background, rim, options);
}

void WriteCoverageImages(const CoverageReport& coverage, const std::filesystem::path& coverage_png,
                         const std::filesystem::path& uncertainty_png) {
  const auto write = [](const std::filesystem::path& path, const cv::Mat& image) {
    std::filesystem::create_directories(path.parent_path());
    cv::imwrite(path.string(), image);
  };
  write(coverage_png, coverage.coverage_image);
  if (coverage.uncertainty_valid) write(uncertainty_png, coverage.uncertainty_image);
}

}  // namespace omnirig
