#include "engine/calib/svp.h"

#include <cmath>
#include <sstream>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "engine/calib/detect.h"
#include "engine/features/image.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {
namespace {

// Algebraic (Kasa) circle fit: u^2 + v^2 + D u + E v + F = 0.
std::optional<Eigen::Vector3d> FitCircle(const std::vector<Eigen::Vector2d>& points) {
  if (points.size() < 3) return std::nullopt;
  Eigen::MatrixXd a(points.size(), 3);
  Eigen::VectorXd b(points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    a.row(i) << points[i].x(), points[i].y(), 1.0;
    b(i) = -points[i].squaredNorm();
  }
  const Eigen::Vector3d x = a.colPivHouseholderQr().solve(b);
  const Eigen::Vector2d centre = -0.5 * x.head<2>();
  const double r2 = centre.squaredNorm() - x(2);
  if (!(r2 > 0.0)) return std::nullopt;
  return Eigen::Vector3d(centre.x(), centre.y(), std::sqrt(r2));
}

double Bilinear(const cv::Mat& grey, double u, double v) {
  const int u0 = static_cast<int>(std::floor(u)), v0 = static_cast<int>(std::floor(v));
  if (u0 < 0 || v0 < 0 || u0 + 1 >= grey.cols || v0 + 1 >= grey.rows) return -1.0;
  const double fu = u - u0, fv = v - v0;
  return (1 - fu) * (1 - fv) * grey.at<uint8_t>(v0, u0) +
         fu * (1 - fv) * grey.at<uint8_t>(v0, u0 + 1) +
         (1 - fu) * fv * grey.at<uint8_t>(v0 + 1, u0) + fu * fv * grey.at<uint8_t>(v0 + 1, u0 + 1);
}

// The strongest intensity step along each radial profile around the predicted circle.
std::vector<Eigen::Vector2d> RadialEdges(const cv::Mat& grey, const Eigen::Vector3d& circle,
                                         const SvpCheckOptions& options) {
  std::vector<Eigen::Vector2d> edges;
  for (int k = 0; k < options.num_profiles; ++k) {
    const double angle = 2.0 * M_PI * k / options.num_profiles;
    const Eigen::Vector2d direction(std::cos(angle), std::sin(angle));
    double best = 0.0, best_r = -1.0;
    for (double r = circle.z() - options.search_margin_px;
         r <= circle.z() + options.search_margin_px; r += 0.5) {
      const Eigen::Vector2d inner = circle.head<2>() + (r - 1.0) * direction;
      const Eigen::Vector2d outer = circle.head<2>() + (r + 1.0) * direction;
      const double a = Bilinear(grey, inner.x(), inner.y());
      const double b = Bilinear(grey, outer.x(), outer.y());
      if (a < 0 || b < 0 || r < 2.0) continue;
      if (std::abs(a - b) > best) {
        best = std::abs(a - b);
        best_r = r;
      }
    }
    if (best > 20.0) edges.push_back(circle.head<2>() + best_r * direction);
  }
  return edges;
}

// Finds the rim's edge on radial profiles around `guess` and fits a circle, re-fitting on the
// inliers of the previous fit so that spurious edges (the scene) drop out.
SvpCheckReport FitRimNear(const cv::Mat& grey, const CameraModel& camera,
                          const Eigen::Vector3d& guess, const SvpCheckOptions& options) {
  SvpCheckReport report;
  report.principal_point_px = Eigen::Vector2d(camera.intrinsics.u0(), camera.intrinsics.v0());
  std::vector<Eigen::Vector2d> edges = RadialEdges(grey, guess, options);
  std::optional<Eigen::Vector3d> circle = FitCircle(edges);
  for (int round = 0; round < 3 && circle; ++round) {
    std::vector<Eigen::Vector2d> inliers;
    for (const auto& p : edges) {
      if (std::abs((p - circle->head<2>()).norm() - circle->z()) <
          4.0 * options.inlier_px / (round + 1)) {
        inliers.push_back(p);
      }
    }
    edges = inliers;
    circle = FitCircle(edges);
  }
  report.num_edge_points = static_cast<int>(edges.size());
  if (!circle || report.num_edge_points < options.num_profiles / 4) {
    report.reason = "no rim edge found around the expected circle (" +
                    std::to_string(report.num_edge_points) + " edge points)";
    return report;
  }
  report.found_circle_px = circle;
  report.principal_point_offset_px = (circle->head<2>() - report.principal_point_px).norm();
  return report;
}

// The radius around `centre` at which the intensity, averaged over the directions whose samples
// lie in the image, changes most: a circle centred near `centre` (the rim) adds up over every
// direction, the scene's edges do not.
std::optional<double> StrongestCircularStep(const cv::Mat& grey, const Eigen::Vector2d& centre,
                                            const SvpCheckOptions& options) {
  const double max_radius = std::hypot(grey.cols, grey.rows);
  const int num_radii = static_cast<int>(max_radius);
  std::vector<double> sum(num_radii, 0.0);
  std::vector<int> count(num_radii, 0);
  for (int k = 0; k < options.num_profiles; ++k) {
    const double angle = 2.0 * M_PI * k / options.num_profiles;
    const Eigen::Vector2d direction(std::cos(angle), std::sin(angle));
    double previous = -1.0;
    for (int r = 0; r < num_radii; ++r) {
      const Eigen::Vector2d p = centre + r * direction;
      const double value = Bilinear(grey, p.x(), p.y());
      if (value < 0) break;
      if (previous >= 0) {
        sum[r] += std::abs(value - previous);
        ++count[r];
      }
      previous = value;
    }
  }
  // Radii seen by fewer than a quarter of the directions (corners of the image) do not count;
  // nor do the innermost ones (the camera's own reflection).
  double best = 0.0;
  int best_r = -1;
  for (int r = std::max(4, num_radii / 20); r < num_radii; ++r) {
    if (4 * count[r] < options.num_profiles) continue;
    const double mean = sum[r] / count[r];
    if (mean > best) {
      best = mean;
      best_r = r;
    }
  }
  if (best_r < 0 || best < 5.0) return std::nullopt;
  return best_r - 0.5;
}

}  // namespace

void MirrorRim::Check() const {
  OMNIRIG_CHECK_POSITIVE(rim_radius_m);
  OMNIRIG_CHECK(std::isfinite(rim_height_m), "svp: rim_height_m must be finite");
}

void SvpCheckOptions::Check() const {
  OMNIRIG_CHECK(search_margin_px > 1.0, "svp: search_margin_px must be > 1");
  OMNIRIG_CHECK_IN(num_profiles, '[', 8, 10000, ']');
  OMNIRIG_CHECK_POSITIVE(inlier_px);
}

SvpCheckReport CheckSingleViewpoint(const cv::Mat& image, const CameraModel& camera,
                                    const MirrorRim& rim, const SvpCheckOptions& options) {
  rim.Check();
  options.Check();
  camera.intrinsics.Check();
  OMNIRIG_CHECK(!image.empty(), "svp: empty image");
  std::vector<Eigen::Vector2d> predicted;
  for (int k = 0; k < 72; ++k) {
    const double angle = 2.0 * M_PI * k / 72;
    const auto pixel = Project(
        camera.intrinsics, Eigen::Vector3d(rim.rim_radius_m * std::cos(angle),
                                           rim.rim_radius_m * std::sin(angle), rim.rim_height_m));
    OMNIRIG_CHECK(pixel, "svp: the rim does not project with this model");
    predicted.push_back(*pixel);
  }
  const std::optional<Eigen::Vector3d> predicted_circle = FitCircle(predicted);
  OMNIRIG_CHECK(predicted_circle, "svp: the projected rim is not a circle");
  SvpCheckReport report = FitRimNear(ToGreyscale8(image), camera, *predicted_circle, options);
  report.predicted_circle_px = predicted_circle;
  if (report.found_circle_px) {
    report.centre_offset_px =
        (report.found_circle_px->head<2>() - predicted_circle->head<2>()).norm();
    report.radius_offset_px = report.found_circle_px->z() - predicted_circle->z();
  }
  return report;
}

SvpCheckReport DetectRim(const cv::Mat& image, const CameraModel& camera,
                         const SvpCheckOptions& options) {
  options.Check();
  camera.intrinsics.Check();
  OMNIRIG_CHECK(!image.empty(), "svp: empty image");
  const cv::Mat grey = ToGreyscale8(image);
  const Eigen::Vector2d centre(camera.intrinsics.u0(), camera.intrinsics.v0());
  const std::optional<double> radius = StrongestCircularStep(grey, centre, options);
  if (!radius) {
    SvpCheckReport report;
    report.principal_point_px = centre;
    report.reason = "no circular edge around the principal point";
    return report;
  }
  return FitRimNear(grey, camera, Eigen::Vector3d(centre.x(), centre.y(), *radius), options);
}

cv::Mat DrawSvpOverlay(const cv::Mat& image, const SvpCheckReport& report) {
  cv::Mat overlay;
  if (image.channels() == 1) {
    cv::cvtColor(image, overlay, cv::COLOR_GRAY2BGR);
  } else {
    overlay = image.clone();
  }
  const auto draw = [&](const Eigen::Vector3d& c, const cv::Scalar& colour) {
    cv::circle(overlay, cv::Point(cvRound(c.x() * 16), cvRound(c.y() * 16)), cvRound(c.z() * 16),
               colour, 1, cv::LINE_AA, 4);
    cv::drawMarker(overlay, cv::Point(cvRound(c.x()), cvRound(c.y())), colour, cv::MARKER_CROSS,
                   12);
  };
  if (report.predicted_circle_px) draw(*report.predicted_circle_px, cv::Scalar(0, 0, 255));
  cv::drawMarker(
      overlay,
      cv::Point(cvRound(report.principal_point_px.x()), cvRound(report.principal_point_px.y())),
      cv::Scalar(255, 128, 0), cv::MARKER_TILTED_CROSS, 12);
  std::ostringstream text;
  text.precision(3);
  if (report.found_circle_px) {
    draw(*report.found_circle_px, cv::Scalar(0, 255, 0));
    if (report.predicted_circle_px) {
      text << "rim offset: centre " << report.centre_offset_px << " px, radius "
           << report.radius_offset_px << " px (red predicted, green found)";
    } else {
      text << "rim (green) centre " << report.principal_point_offset_px
           << " px from the principal point (blue)";
    }
  } else {
    text << report.reason;
  }
  cv::putText(overlay, text.str(), cv::Point(8, 20), cv::FONT_HERSHEY_SIMPLEX, 0.5,
              cv::Scalar(0, 0, 0), 3, cv::LINE_AA);
  cv::putText(overlay, text.str(), cv::Point(8, 20), cv::FONT_HERSHEY_SIMPLEX, 0.5,
              cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  return overlay;
}

}  // namespace omnirig
