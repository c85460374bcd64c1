#include "engine/slam/evaluation.h"

#include <random>

#include <gtest/gtest.h>

#include "engine/util/check.h"

namespace omnirig::slam {
namespace {

std::vector<Rigid3d> Circle(int n) {
  std::vector<Rigid3d> poses;
  for (int i = 0; i < n; ++i) {
    const double a = 0.1 * i;
    poses.emplace_back(Eigen::Quaterniond(Eigen::AngleAxisd(a, Eigen::Vector3d::UnitZ())),
                       Eigen::Vector3d(3 * std::cos(a), 3 * std::sin(a), 0.1 * i));
  }
  return poses;
}

TEST(AlignRigid, RecoversAKnownTransform) {
  const Rigid3d dst_from_src(Eigen::Quaterniond(Eigen::AngleAxisd(1.0, Eigen::Vector3d(1, -1, 2).normalized())),
                             Eigen::Vector3d(0.5, -2, 7));
  std::vector<Eigen::Vector3d> src, dst;
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-3, 3);
  for (int i = 0; i < 20; ++i) {
    src.emplace_back(u(rng), u(rng), u(rng));
    dst.push_back(dst_from_src * src.back());
  }
  const Rigid3d estimate = AlignRigid(src, dst);
  EXPECT_LT(RotationDistanceRad(estimate.rotation, dst_from_src.rotation), 1e-12);
  EXPECT_LT((estimate.translation - dst_from_src.translation).norm(), 1e-12);
}

TEST(EvaluateTrajectory, ZeroForARigidlyMovedCopy) {
  const std::vector<Rigid3d> gt = Circle(30);
  const Rigid3d moved(Eigen::Quaterniond(Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitY())),
                      Eigen::Vector3d(1, 2, 3));
  std::vector<Rigid3d> estimate;
  for (const Rigid3d& pose : gt) estimate.push_back(moved * pose);
  const TrajectoryErrors errors = EvaluateTrajectory(estimate, gt);
  EXPECT_LT(errors.ate_rmse_m, 1e-12);
  EXPECT_LT(errors.rpe_translation_rmse_m, 1e-12);
  EXPECT_LT(errors.rpe_rotation_rmse_deg, 1e-6);
  EXPECT_LT(errors.final_drift_percent, 1e-9);
  EXPECT_LT(RotationDistanceRad(errors.gt_from_estimate.rotation, moved.rotation.conjugate()), 1e-9);
}

TEST(EvaluateTrajectory, ErrorsOverDistanceAndSegmentsOfFixedLength) {
  const std::vector<Rigid3d> gt = Circle(30);  // 29 steps of ~0.32 m: ~9.2 m in all
  std::vector<Rigid3d> estimate;
  for (const Rigid3d& pose : gt) {
    estimate.emplace_back(pose.rotation, gt[0].translation + 1.02 * (pose.translation - gt[0].translation));
  }
  const TrajectoryErrors exact = EvaluateTrajectory(gt, gt);
  ASSERT_EQ(exact.segments.size(), 2u);
  EXPECT_EQ(exact.segments[0].length_m, 1.0);
  EXPECT_GT(exact.segments[0].num_segments, 20);
  EXPECT_LT(exact.segments[0].translation_rmse_m, 1e-12);
  EXPECT_EQ(exact.segments[1].num_segments, 0);  // the path is shorter than 10 m

  const TrajectoryErrors errors = EvaluateTrajectory(estimate, gt, {1.0, 5.0});
  ASSERT_EQ(errors.distance_m.size(), gt.size());
  ASSERT_EQ(errors.translation_error_m.size(), gt.size());
  ASSERT_EQ(errors.rotation_error_deg.size(), gt.size());
  EXPECT_DOUBLE_EQ(errors.distance_m.front(), 0.0);
  EXPECT_DOUBLE_EQ(errors.distance_m.back(), errors.path_length_m);
  double sum_sq = 0;
  for (const double e : errors.translation_error_m) sum_sq += e * e;
  EXPECT_NEAR(std::sqrt(sum_sq / gt.size()), errors.ate_rmse_m, 1e-12);
  // 2 % too long: every segment's translation error is 2 % of its chord, so a little less of
  // its path along the circle (radius 3 m), and the less the longer the segment.
  for (const SegmentErrors& segment : errors.segments) {
    EXPECT_GT(segment.num_segments, 0);
    EXPECT_LE(segment.translation_mean_percent, 2.0 + 1e-9);
    EXPECT_LT(segment.rotation_rmse_deg, 1e-6);
  }
  EXPECT_GT(errors.segments[0].translation_mean_percent, 1.95);
  EXPECT_LT(errors.segments[1].translation_mean_percent, errors.segments[0].translation_mean_percent);
  EXPECT_THROW(EvaluateTrajectory(estimate, gt, {0.0}), InvalidArgument);
}

TEST(EvaluateTrajectory, MeasuresAScaleDriftAndAnOffset) {
  const std::vector<Rigid3d> gt = Circle(30);
  // 2% too long: every position scaled about the first pose.
  std::vector<Rigid3d> estimate;
  for (const Rigid3d& pose : gt) {
    estimate.emplace_back(pose.rotation, gt[0].translation + 1.02 * (pose.translation - gt[0].translation));
  }
  const TrajectoryErrors errors = EvaluateTrajectory(estimate, gt);
  const double chord = (gt.back().translation - gt.front().translation).norm();
  EXPECT_NEAR(errors.final_drift_percent, 100 * 0.02 * chord / errors.path_length_m, 1e-9);
  EXPECT_GT(errors.ate_rmse_m, 0.0);
  EXPECT_LT(errors.ate_rmse_m, 0.02 * chord);

  // A constant 5 cm translation of every estimated pose: the SE(3) alignment removes it.
  std::vector<Rigid3d> shifted;
  for (const Rigid3d& pose : gt) shifted.emplace_back(pose.rotation, pose.translation + Eigen::Vector3d(0.05, 0, 0));
  EXPECT_LT(EvaluateTrajectory(shifted, gt).ate_rmse_m, 1e-9);
  EXPECT_LT(EvaluateTrajectory(shifted, gt).rpe_translation_rmse_m, 1e-9);
}

TEST(EvaluateTrajectory, RpeSeesOneBadStep) {
  const std::vector<Rigid3d> gt = Circle(10);
  std::vector<Rigid3d> estimate = gt;
  for (size_t i = 5; i < estimate.size(); ++i) {
    // A world-frame jump between frames 4 and 5: only that step's relative pose is wrong.
    estimate[i] = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0.1, 0, 0)) * estimate[i];
  }
  const TrajectoryErrors errors = EvaluateTrajectory(estimate, gt);
  EXPECT_NEAR(errors.rpe_translation_rmse_m, std::sqrt(0.01 / 9), 1e-9);
}

TEST(EvaluateTrajectory, RejectsMismatchedLengths) {
  EXPECT_THROW(EvaluateTrajectory(Circle(3), Circle(4)), InvalidArgument);
}

}  // namespace
}  // namespace omnirig::slam
