#include "engine/calib/svp.h"

#include <cmath>
#include <sstream>

#include <Eigen/Dense>
#include <opencv2/imgproc.hpp>

#include "engine/util/check.h"

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
  return (1 - fu) * (1 - fv) * grey.at<uint8_t>(v0, u0) + fu * (1 - fv) * grey.at<uint8_t>(v0, u0 + 1) +
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

}  // namespace

void MirrorRim::Check() const {
  OMNIRIG_CHECK(rim_radius_m > 0.0 && std::isfinite(rim_radius_m),
                "svp: rim_radius_m must be positive");
  OMNIRIG_CHECK(std::isfinite(rim_height_m), "svp: rim_height_m must be finite");
}

void SvpCheckOptions::Check() const {
  OMNIRIG_CHECK(search_margin_px > 1.0, "svp: search_margin_px must be > 1");
  OMNIRIG_CHECK(num_profiles >= 8 && num_profiles <= 10000, "svp: num_profiles in [8, 10000]");
  OMNIRIG_CHECK(inlier_px > 0.0, "svp: inlier_px must be positive");
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
    const auto pixel = Project(camera.intrinsics,
                               Eigen::Vector3d(rim.rim_radius_m * std::cos(angle),
                                               rim.rim_radius_m * std::sin(angle),
                                               rim.rim_height_m));
    OMNIRIG_CHECK(pixel, "svp: the rim does not project with this model");
    predicted.push_back(*pixel);
  }
  SvpCheckReport report;
  report.predicted_circle_px = *FitCircle(predicted);
  cv::Mat grey;
  if (image.channels() == 3) {
    cv::cvtColor(image, grey, cv::COLOR_BGR2GRAY);
  } else {
    grey = image;
  }
  std::vector<Eigen::Vector2d> edges = RadialEdges(grey, report.predicted_circle_px, options);
  std::optional<Eigen::Vector3d> circle = FitCircle(edges);
  // Re-fit on the inliers of the previous fit: spurious edges (the scene) drop out.
  for (int round = 0; round < 3 && circle; ++round) {
    std::vector<Eigen::Vector2d> inliers;
    for (const auto& p : edges) {
      if (std::abs((p - circle->head<2>()).norm() - circle->z()) < 4.0 * options.inlier_px / (round + 1)) {
        inliers.push_back(p);
      }
    }
    edges = inliers;
    circle = FitCircle(edges);
  }
  report.num_edge_points = static_cast<int>(edges.size());
  if (!circle || report.num_edge_points < options.num_profiles / 4) {
    report.reason = "no rim edge found around the predicted circle (" +
                    std::to_string(report.num_edge_points) + " edge points)";
    return report;
  }
  report.found_circle_px = circle;
  report.centre_offset_px = (circle->head<2>() - report.predicted_circle_px.head<2>()).norm();
  report.radius_offset_px = circle->z() - report.predicted_circle_px.z();
  return report;
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
    cv::drawMarker(overlay, cv::Point(cvRound(c.x()), cvRound(c.y())), colour, cv::MARKER_CROSS, 12);
  };
  draw(report.predicted_circle_px, cv::Scalar(0, 0, 255));
  std::ostringstream text;
  text.precision(3);
  if (report.found_circle_px) {
    draw(*report.found_circle_px, cv::Scalar(0, 255, 0));
    text << "rim offset: centre " << report.centre_offset_px << " px, radius "
         << report.radius_offset_px << " px (red predicted, green found)";
  } else {
    text << report.reason;
  }
  cv::putText(overlay, text.str(), cv::Point(8, 20), cv::FONT_HERSHEY_SIMPLEX, 0.5,
              cv::Scalar(255, 255, 255), 1, cv::LINE_AA);
  return overlay;
}

}  // namespace omnirig
