#include "engine/calib/coverage.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
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

// The disk's regions: 12 clock sectors of 30 deg (sector k from (k + 3) o'clock, azimuth 30 k
// deg) times three rings.
constexpr int kNumSectors = 12;
constexpr int kNumRings = 3;
constexpr const char* kRingNames[kNumRings] = {"inner", "middle", "outer"};

// Per region: the grid pixels in it and those near a corner.
struct RegionCounts {
  std::array<std::array<int, kNumSectors>, kNumRings> in{}, covered{};
};

// The region of pixel offset (from the disk's centre) within a disk of `radius`: {ring, sector}.
std::array<int, 2> RegionOf(const Eigen::Vector2d& offset, double radius) {
  const double r = offset.norm() / radius;
  double azimuth = std::atan2(offset.y(), offset.x()) * 180.0 / M_PI;
  if (azimuth < 0.0) azimuth += 360.0;
  const int ring = r < 0.4 ? 0 : (r < 0.7 ? 1 : 2);
  return {ring, std::min(kNumSectors - 1, static_cast<int>(azimuth / 30.0))};
}

int HourOf(int sector) { return (sector + 2) % 12 + 1; }  // sector 0 starts at 3 o'clock

// The coverage map and its fraction; the counts per region into `counts`.
cv::Mat Coverage(const CalibrationReport& report, const CoverageOptions& options,
                 CoverageReport* coverage, RegionCounts* counts) {
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
  const Eigen::Vector2d& c = coverage->disk_centre_px;
  const double radius = coverage->disk_radius_px;
  int in_disk = 0, covered = 0;
  for (int v = 0; v < height; v += options.grid_step_px) {
    for (int u = 0; u < width; u += options.grid_step_px) {
      const Eigen::Vector2d offset(u - c.x(), v - c.y());
      if (offset.norm() > radius) continue;
      const auto [ring, sector] = RegionOf(offset, radius);
      const bool near = distance.at<float>(v, u) <= options.near_px;
      ++in_disk;
      covered += near;
      ++counts->in[ring][sector];
      counts->covered[ring][sector] += near;
    }
  }
  coverage->covered_fraction = in_disk > 0 ? static_cast<double>(covered) / in_disk : 0.0;
  return distance;
}

// The median uncertainty (px) per region of the map, 0 where it has no value.
std::array<std::array<double, kNumSectors>, kNumRings> RegionUncertainty(
    const CoverageReport& coverage) {
  std::array<std::array<std::vector<float>, kNumSectors>, kNumRings> values;
  const cv::Mat& map = coverage.uncertainty_px;
  for (int row = 0; row < map.rows; ++row) {
    for (int col = 0; col < map.cols; ++col) {
      const float value = map.at<float>(row, col);
      if (!(value > 0.0f)) continue;
      const Eigen::Vector2d offset =
          Eigen::Vector2d(col, row) * coverage.uncertainty_step_px - coverage.disk_centre_px;
      if (offset.norm() > coverage.disk_radius_px) continue;
      const auto [ring, sector] = RegionOf(offset, coverage.disk_radius_px);
      values[ring][sector].push_back(value);
    }
  }
  std::array<std::array<double, kNumSectors>, kNumRings> medians{};
  for (int ring = 0; ring < kNumRings; ++ring) {
    for (int sector = 0; sector < kNumSectors; ++sector) {
      auto& v = values[ring][sector];
      if (v.empty()) continue;
      std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
      medians[ring][sector] = v[v.size() / 2];
    }
  }
  return medians;
}

// The flagged sectors of each ring as regions, neighbouring sectors (also across 3 o'clock)
// joined; `value` gives a region's figures from its sectors.
std::vector<CoverageReport::Region> JoinSectors(
    const std::array<std::array<bool, kNumSectors>, kNumRings>& flagged,
    const std::function<void(int ring, const std::vector<int>& sectors, CoverageReport::Region*)>&
        value) {
  std::vector<CoverageReport::Region> regions;
  for (int ring = kNumRings - 1; ring >= 0; --ring) {
    const auto& f = flagged[ring];
    const int first_clear = static_cast<int>(std::find(f.begin(), f.end(), false) - f.begin());
    std::vector<int> run;
    const auto close = [&](int end_sector) {
      if (run.empty()) return;
      CoverageReport::Region region;
      region.ring = kRingNames[ring];
      region.from_hour = HourOf(run.front());
      region.to_hour = HourOf(end_sector % kNumSectors);
      value(ring, run, &region);
      regions.push_back(region);
      run.clear();
    };
    if (first_clear == kNumSectors) {  // all around
      for (int s = 0; s < kNumSectors; ++s) run.push_back(s);
      close(0);
      continue;
    }
    // Start after a clear sector so that a run across sector 11 -> 0 stays whole.
    for (int i = 1; i <= kNumSectors; ++i) {
      const int s = (first_clear + i) % kNumSectors;
      if (f[s]) {
        run.push_back(s);
      } else {
        close(s);
      }
    }
  }
  return regions;
}

std::string RegionText(const CoverageReport::Region& region) {
  std::ostringstream os;
  os << "the " << region.ring << " ring";
  if (region.ring == "outer") os << " (near the rim)";
  if (region.from_hour == region.to_hour) {
    os << ", all around";
  } else {
    os << ", " << region.from_hour << " to " << region.to_hour << " o'clock";
  }
  return os.str();
}

// The board poses of the used views: how far and how tilted; the poses missing among tilted,
// near and far.
void BoardPoses(const CalibrationReport& report, const BoardSpec& board,
                const CoverageOptions& options, CoverageReport* coverage) {
  const std::vector<Eigen::Vector3d> object_points = board.ObjectPoints();
  Eigen::Vector3d board_centre = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& x : object_points) board_centre += x / object_points.size();
  std::vector<double> distances;
  double max_tilt_deg = 0.0;
  for (const CalibrationImageReport& image : report.images) {
    if (!image.used) continue;
    const Eigen::Vector3d centre = image.cam_from_board * board_centre;
    const Eigen::Vector3d normal = image.cam_from_board.rotation * Eigen::Vector3d::UnitZ();
    const double cosine = std::abs(normal.dot(centre.normalized()));
    max_tilt_deg = std::max(max_tilt_deg, std::acos(std::min(1.0, cosine)) * 180.0 / M_PI);
    distances.push_back(centre.norm());
  }
  if (distances.empty()) return;
  std::sort(distances.begin(), distances.end());
  coverage->median_board_distance_m = distances[distances.size() / 2];
  coverage->min_board_distance_m = distances.front();
  coverage->max_board_distance_m = distances.back();
  coverage->max_tilt_deg = max_tilt_deg;
  if (max_tilt_deg < options.tilted_deg) coverage->missing_poses.push_back("tilted");
  if (distances.front() > options.near_ratio * coverage->median_board_distance_m) {
    coverage->missing_poses.push_back("near");
  }
  if (distances.back() < options.far_ratio * coverage->median_board_distance_m) {
    coverage->missing_poses.push_back("far");
  }
}

std::string PoseAdvice(const std::string& pose, const CoverageReport& coverage,
                       const CoverageOptions& options) {
  std::ostringstream os;
  os.precision(2);
  if (pose == "tilted") {
    os << "no tilted board: every used view faces the camera within "
       << std::lround(coverage.max_tilt_deg) << " deg; add views with the board tilted "
       << std::lround(options.tilted_deg) << " to 60 deg away from the camera";
  } else if (pose == "near") {
    os << "no near board: the nearest is " << coverage.min_board_distance_m << " m away (median "
       << coverage.median_board_distance_m << " m); add views with the board at "
       << options.near_ratio * coverage.median_board_distance_m
       << " m or nearer, filling more of the mirror";
  } else {
    os << "no far board: the farthest is " << coverage.max_board_distance_m << " m away (median "
       << coverage.median_board_distance_m << " m); add views with the board at "
       << options.far_ratio * coverage.median_board_distance_m
       << " m or farther, at the distances the camera will work at";
  }
  return os.str();
}

// The regions with no corner, and until the uncertainty map is flat, its highest regions and
// the missing board poses, as structured lists and sentences.
void Advise(const CalibrationReport& report, const BoardSpec& board, const RegionCounts& counts,
            const CoverageOptions& options, CoverageReport* coverage) {
  std::array<std::array<bool, kNumSectors>, kNumRings> uncovered{};
  for (int ring = 0; ring < kNumRings; ++ring) {
    for (int s = 0; s < kNumSectors; ++s) {
      const int n = counts.in[ring][s];
      uncovered[ring][s] = n > 0 && counts.covered[ring][s] < options.min_sector_coverage * n;
    }
  }
  const auto medians = coverage->uncertainty_valid
                           ? RegionUncertainty(*coverage)
                           : std::array<std::array<double, kNumSectors>, kNumRings>{};
  const auto figures = [&](int ring, const std::vector<int>& sectors, CoverageReport::Region* r) {
    int in = 0, covered = 0;
    for (int s : sectors) {
      in += counts.in[ring][s];
      covered += counts.covered[ring][s];
      r->median_uncertainty_px = std::max(r->median_uncertainty_px, medians[ring][s]);
    }
    r->covered_fraction = in > 0 ? static_cast<double>(covered) / in : 0.0;
  };
  coverage->uncovered_regions = JoinSectors(uncovered, figures);
  for (const CoverageReport::Region& region : coverage->uncovered_regions) {
    coverage->advice.push_back("no corner in " + RegionText(region) +
                               ": add views with the board there");
  }
  std::array<std::array<bool, kNumSectors>, kNumRings> uncertain{};
  bool any_uncertain = false;
  for (int ring = 0; ring < kNumRings; ++ring) {
    for (int s = 0; s < kNumSectors; ++s) {
      uncertain[ring][s] =
          medians[ring][s] > options.flat_uncertainty_ratio * coverage->median_uncertainty_px;
      any_uncertain = any_uncertain || uncertain[ring][s];
    }
  }
  coverage->uncertainty_flat = coverage->uncertainty_valid && !any_uncertain;
  if (any_uncertain) coverage->uncertain_regions = JoinSectors(uncertain, figures);
  BoardPoses(report, board, options, coverage);
  if (coverage->uncertainty_flat) return;
  for (const CoverageReport::Region& region : coverage->uncertain_regions) {
    std::ostringstream os;
    os.precision(2);
    os << "the uncertainty is highest in " << RegionText(region) << " ("
       << region.median_uncertainty_px << " px against " << coverage->median_uncertainty_px
       << " px over the disk): add views with the board there";
    coverage->advice.push_back(os.str());
  }
  for (const std::string& pose : coverage->missing_poses) {
    coverage->advice.push_back(PoseAdvice(pose, *coverage, options));
  }
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
  OMNIRIG_CHECK_IN(min_sector_coverage, '[', 0, 1, ']');
  OMNIRIG_CHECK_AT_LEAST(flat_uncertainty_ratio, 1.0);
  OMNIRIG_CHECK_IN(tilted_deg, '[', 0, 90, ']');
  OMNIRIG_CHECK_IN(near_ratio, '(', 0, 1, ']');
  OMNIRIG_CHECK_AT_LEAST(far_ratio, 1.0);
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
  RegionCounts counts;
  const cv::Mat distance = Coverage(report, options, &coverage, &counts);
  coverage.coverage_image = DrawCoverage(background, distance, report, options, coverage);
  const cv::Mat sigma = Uncertainty(report, board, options, &coverage);
  if (!sigma.empty()) coverage.uncertainty_image = DrawUncertainty(sigma, report, coverage);
  Advise(report, board, counts, options, &coverage);
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
