#include "engine/slam/evaluation.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include <Eigen/SVD>

#include "engine/util/check.h"

namespace omnirig::slam {
namespace {

double RadToDeg(double rad) { return rad * 180.0 / M_PI; }

SegmentErrors EvaluateSegments(const std::vector<Rigid3d>& estimate,
                               const std::vector<Rigid3d>& gt,
                               const std::vector<double>& distance_m, double length_m) {
  SegmentErrors segments;
  segments.length_m = length_m;
  double t_sq = 0, r_sq = 0, percent = 0;
  size_t end = 0;
  for (size_t begin = 0; begin < gt.size(); ++begin) {
    end = std::max(end, begin + 1);
    while (end < gt.size() && distance_m[end] - distance_m[begin] < length_m) ++end;
    if (end == gt.size()) break;
    const Rigid3d gt_delta = gt[begin].Inverse() * gt[end];
    const Rigid3d est_delta = estimate[begin].Inverse() * estimate[end];
    const double t = (gt_delta.Inverse() * est_delta).translation.norm();
    const double r = RadToDeg(RotationDistanceRad(gt_delta.rotation, est_delta.rotation));
    t_sq += t * t;
    r_sq += r * r;
    percent += 100.0 * t / (distance_m[end] - distance_m[begin]);
    ++segments.num_segments;
  }
  if (segments.num_segments == 0) return segments;
  segments.translation_rmse_m = std::sqrt(t_sq / segments.num_segments);
  segments.rotation_rmse_deg = std::sqrt(r_sq / segments.num_segments);
  segments.translation_mean_percent = percent / segments.num_segments;
  return segments;
}

}  // namespace

TrajectoryErrors EvaluateTrajectory(const std::vector<Rigid3d>& estimate,
                                    const std::vector<Rigid3d>& gt,
                                    const std::vector<double>& segment_lengths_m) {
  for (const double length : segment_lengths_m) {
    OMNIRIG_CHECK(length > 0, "segment length " << length << " m is not positive");
  }
  OMNIRIG_CHECK(estimate.size() == gt.size(),
                "trajectory has " << estimate.size() << " poses, ground truth " << gt.size());
  OMNIRIG_CHECK(gt.size() >= 2, "evaluation needs at least two poses");
  TrajectoryErrors errors;
  errors.num_poses = static_cast<int>(gt.size());

  std::vector<Eigen::Vector3d> est_positions, gt_positions;
  for (size_t i = 0; i < gt.size(); ++i) {
    est_positions.push_back(estimate[i].translation);
    gt_positions.push_back(gt[i].translation);
  }
  errors.gt_from_estimate = AlignRigid(est_positions, gt_positions);
  double sum_sq = 0;
  for (size_t i = 0; i < gt.size(); ++i) {
    const double e = (errors.gt_from_estimate * est_positions[i] - gt_positions[i]).norm();
    sum_sq += e * e;
    errors.ate_max_m = std::max(errors.ate_max_m, e);
    errors.translation_error_m.push_back(e);
    errors.rotation_error_deg.push_back(RadToDeg(RotationDistanceRad(
        errors.gt_from_estimate.rotation * estimate[i].rotation, gt[i].rotation)));
  }
  errors.ate_rmse_m = std::sqrt(sum_sq / gt.size());

  double rpe_t_sq = 0, rpe_r_sq = 0;
  for (size_t i = 0; i + 1 < gt.size(); ++i) {
    const Rigid3d gt_delta = gt[i].Inverse() * gt[i + 1];
    const Rigid3d est_delta = estimate[i].Inverse() * estimate[i + 1];
    const Rigid3d error = gt_delta.Inverse() * est_delta;
    rpe_t_sq += error.translation.squaredNorm();
    const double angle_deg = RadToDeg(RotationDistanceRad(gt_delta.rotation, est_delta.rotation));
    rpe_r_sq += angle_deg * angle_deg;
  }
  errors.rpe_translation_rmse_m = std::sqrt(rpe_t_sq / (gt.size() - 1));
  errors.rpe_rotation_rmse_deg = std::sqrt(rpe_r_sq / (gt.size() - 1));

  // Anchor both at their first pose: gt_from_est_anchor maps the estimate's first pose onto
  // the ground truth's. The largest drift only counts poses past a quarter of the path, where
  // a percentage of the distance so far is meaningful.
  const Rigid3d gt_from_est_anchor = gt.front() * estimate.front().Inverse();
  std::vector<double> distance_so_far(gt.size(), 0.0);
  for (size_t i = 1; i < gt.size(); ++i) {
    distance_so_far[i] =
        distance_so_far[i - 1] + (gt[i].translation - gt[i - 1].translation).norm();
  }
  errors.path_length_m = distance_so_far.back();
  errors.distance_m = distance_so_far;
  for (const double length : segment_lengths_m) {
    errors.segments.push_back(EvaluateSegments(estimate, gt, distance_so_far, length));
  }
  if (errors.path_length_m <= 1e-9) return errors;
  for (size_t i = 1; i < gt.size(); ++i) {
    const double e = (gt_from_est_anchor * estimate[i].translation - gt[i].translation).norm();
    if (distance_so_far[i] >= 0.25 * errors.path_length_m) {
      errors.max_drift_percent = std::max(errors.max_drift_percent, 100.0 * e / distance_so_far[i]);
    }
    if (i + 1 == gt.size()) errors.final_drift_percent = 100.0 * e / errors.path_length_m;
  }
  return errors;
}

double CalibrationPixelRms(const UnifiedIntrinsics& truth, const UnifiedIntrinsics& estimate,
                           double min_radius_px, double max_radius_px) {
  const Eigen::Vector2d centre(truth.u0(), truth.v0());
  double sum_sq = 0;
  int count = 0;
  for (double dv = -max_radius_px; dv <= max_radius_px; dv += 4) {
    for (double du = -max_radius_px; du <= max_radius_px; du += 4) {
      const double r = std::hypot(du, dv);
      if (r < min_radius_px || r > max_radius_px) continue;
      const Eigen::Vector2d pixel = centre + Eigen::Vector2d(du, dv);
      const std::optional<Eigen::Vector3d> bearing = Lift(truth, pixel);
      if (!bearing) continue;
      const std::optional<Eigen::Vector2d> projected = Project(estimate, *bearing);
      if (!projected) continue;
      sum_sq += (*projected - pixel).squaredNorm();
      ++count;
    }
  }
  return count > 0 ? std::sqrt(sum_sq / count) : 0.0;
}

}  // namespace omnirig::slam
