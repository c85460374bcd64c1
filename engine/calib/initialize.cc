#include "engine/calib/initialize.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/SVD>

#include "engine/estimators/board_pose.h"

namespace omnirig {
namespace {

CameraModel UnifiedGuess(double gamma, const Eigen::Vector2d& principal_point_px, int width,
                         int height) {
  CameraModel camera;
  camera.width = width;
  camera.height = height;
  camera.intrinsics.xi() = 1.0;
  camera.intrinsics.gamma_u() = camera.intrinsics.gamma_v() = gamma;
  camera.intrinsics.u0() = principal_point_px.x();
  camera.intrinsics.v0() = principal_point_px.y();
  return camera;
}

// Linear pose of one view under `camera` and its RMS (infinity when it fails).
double LinearViewRms(const CameraModel& camera, const InitView& view) {
  std::vector<Eigen::Vector3d> bearings;
  bearings.reserve(view.corners_px.size());
  for (const auto& corner : view.corners_px) {
    const auto bearing = Lift(camera.intrinsics, corner);
    if (!bearing) return std::numeric_limits<double>::infinity();
    bearings.push_back(*bearing);
  }
  const auto cam_from_board = BoardPoseFromBearings(view.object_points, bearings);
  if (!cam_from_board) return std::numeric_limits<double>::infinity();
  double sum2 = 0.0;
  for (size_t i = 0; i < view.object_points.size(); ++i) {
    const auto pixel = Project(camera.intrinsics, *cam_from_board * view.object_points[i]);
    if (!pixel) return std::numeric_limits<double>::infinity();
    sum2 += (*pixel - view.corners_px[i]).squaredNorm();
  }
  return std::sqrt(sum2 / static_cast<double>(view.object_points.size()));
}

double Median(std::vector<double> values) {
  if (values.empty()) return std::numeric_limits<double>::infinity();
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  return values[mid];
}

// Gamma candidates: quantiles of the per-line estimates plus a ladder over the image size, so
// that a set without a usable line still initialises.
std::vector<double> GammaCandidates(const std::vector<InitView>& views,
                                    const Eigen::Vector2d& principal_point_px, int width,
                                    int height) {
  const double size = std::max(width, height);
  std::vector<double> estimates;
  for (const InitView& view : views) {
    for (const auto& line : view.lines) {
      std::vector<Eigen::Vector2d> pixels;
      for (int i : line) pixels.push_back(view.corners_px[i]);
      const auto gamma = GammaFromLine(pixels, principal_point_px);
      if (gamma && *gamma > 0.02 * size && *gamma < 50.0 * size) estimates.push_back(*gamma);
    }
  }
  std::vector<double> candidates;
  std::sort(estimates.begin(), estimates.end());
  if (!estimates.empty()) {
    for (int q = 1; q < 20; ++q) {
      candidates.push_back(estimates[estimates.size() * q / 20]);
    }
  }
  for (double factor : {0.1, 0.2, 0.3, 0.5, 0.75, 1.0, 1.5, 2.5}) {
    candidates.push_back(factor * size);
  }
  return candidates;
}

}  // namespace

std::optional<double> GammaFromLine(const std::vector<Eigen::Vector2d>& pixels,
                                    const Eigen::Vector2d& principal_point_px) {
  if (pixels.size() < 3) return std::nullopt;
  // Scaled coordinates keep the four columns comparable: u = s u', rho^2 = s^2 rho'^2.
  double scale = 0.0;
  for (const auto& p : pixels) scale = std::max(scale, (p - principal_point_px).norm());
  if (!(scale > 0.0)) return std::nullopt;
  Eigen::MatrixXd a(pixels.size(), 4);
  for (size_t i = 0; i < pixels.size(); ++i) {
    const Eigen::Vector2d m = (pixels[i] - principal_point_px) / scale;
    a.row(i) << m.x(), m.y(), 1.0, m.squaredNorm();
  }
  const Eigen::JacobiSVD<Eigen::MatrixXd> svd(a, Eigen::ComputeFullV);
  const Eigen::Vector4d c = svd.matrixV().col(3);
  // A line through the centre makes (u, v) alone explain the points: c3 and c4 vanish.
  if (std::hypot(c(2), c(3)) < 1e-3 * std::hypot(c(0), c(1))) return std::nullopt;
  const double gamma2 = -c(2) / c(3) * scale * scale;
  if (!(gamma2 > 0.0) || !std::isfinite(gamma2)) return std::nullopt;
  return std::sqrt(gamma2);
}

std::optional<InitResult> InitializeUnified(
    const std::vector<InitView>& views, int width, int height,
    const std::vector<Eigen::Vector2d>& principal_points) {
  std::optional<InitResult> best;
  for (const Eigen::Vector2d& principal_point : principal_points) {
    for (double gamma : GammaCandidates(views, principal_point, width, height)) {
      const CameraModel camera = UnifiedGuess(gamma, principal_point, width, height);
      std::vector<double> rms;
      for (const InitView& view : views) rms.push_back(LinearViewRms(camera, view));
      const double score = Median(rms);
      if (std::isfinite(score) && (!best || score < best->score_px)) {
        best = InitResult{camera, {}, score};
      }
    }
  }
  if (!best) return std::nullopt;
  bool any_pose = false;
  for (const InitView& view : views) {
    best->cam_from_board.push_back(
        EstimateBoardPose(best->camera, view.object_points, view.corners_px));
    any_pose = any_pose || best->cam_from_board.back().has_value();
  }
  if (!any_pose) return std::nullopt;
  return best;
}

}  // namespace omnirig
