#include "engine/stereo/relative_pose.h"

#include <cmath>
#include <random>

#include <ceres/ceres.h>
#include <gtest/gtest.h>

#include "engine/stereo/relpose_corner_order.h"
#include "engine/stereo/relpose_cost.h"
#include "engine/stereo/relpose_linear.h"

namespace omnirig {
namespace {

constexpr double kDegPerRad = 180.0 / M_PI;

// A hyperbolic-mirror-like camera of 1024 x 768 (the camera's +z points down from the mirror
// towards the camera, so the horizon images on a ring around the principal point).
CameraModel MakeCamera(double gamma, double u0, double v0) {
  CameraModel camera;
  camera.width = 1024;
  camera.height = 768;
  camera.intrinsics.params = {0.94, gamma, gamma * 1.002, u0, v0, 0.0,
                              -0.06, 0.012, 0.0004, -0.0003, 0.0};
  return camera;
}

// The paper's vertical rig: cam1 100 mm above cam0 (above = -z in these camera frames), with a
// small misalignment.
Rigid3d VerticalRig() {
  const Eigen::Quaterniond rotation(Eigen::AngleAxisd(0.8 / kDegPerRad,
                                                      Eigen::Vector3d(0.3, -0.5, 1.0).normalized()));
  return Rigid3d(rotation, Eigen::Vector3d(0.0021, -0.0013, -0.0998));
}

// A board facing the rig at `azimuth_deg` around it, `distance_m` away, tilted a little.
Rigid3d BoardPose(const BoardSpec& board, double azimuth_deg, double distance_m,
                  double tilt_deg, double height_m) {
  const double a = azimuth_deg / kDegPerRad;
  const Eigen::Vector3d centre(distance_m * std::cos(a), distance_m * std::sin(a), height_m);
  const Eigen::Vector3d z_axis = Eigen::Vector3d(centre.x(), centre.y(), 0.0).normalized();
  const Eigen::Vector3d x_axis(-std::sin(a), std::cos(a), 0.0);
  Eigen::Matrix3d facing;
  facing << x_axis, z_axis.cross(x_axis), z_axis;
  const Eigen::Matrix3d tilt =
      Eigen::AngleAxisd(tilt_deg / kDegPerRad, Eigen::Vector3d(1.0, 0.6, 0.2).normalized())
          .toRotationMatrix();
  const Eigen::Matrix3d rotation = facing * tilt;
  const Eigen::Vector3d board_centre(0.5 * (board.cols - 1) * board.square_size_m,
                                     0.5 * (board.rows - 1) * board.square_size_m, 0.0);
  return Rigid3d(Eigen::Quaterniond(rotation), centre - rotation * board_centre);
}

BoardDetection Detect(const CameraModel& camera, const BoardSpec& board,
                      const Rigid3d& cam_from_board, double noise_px, std::mt19937* rng) {
  std::normal_distribution<double> noise(0.0, noise_px);
  BoardDetection detection;
  const std::vector<Eigen::Vector3d> object_points = board.ObjectPoints();
  for (size_t id = 0; id < object_points.size(); ++id) {
    const auto pixel = Project(camera.intrinsics, cam_from_board * object_points[id]);
    if (!pixel) continue;
    const Eigen::Vector2d offset = noise_px > 0.0 ? Eigen::Vector2d(noise(*rng), noise(*rng))
                                                  : Eigen::Vector2d::Zero();
    detection.corners_px.push_back(*pixel + offset);
    detection.corner_ids.push_back(static_cast<int>(id));
  }
  detection.found = detection.corners_px.size() == object_points.size();
  if (!detection.found) detection.reason = "corners outside the image";
  return detection;
}

// Renumbers a detection as if the detector had started from the other end of the grid.
void HalfTurn(const BoardSpec& board, BoardDetection* detection) {
  for (int& id : detection->corner_ids) id = board.NumCorners() - 1 - id;
}

struct Scene {
  BoardSpec board;
  StereoRig rig;
  std::vector<StereoBoardPair> pairs;
};

Scene MakeScene(double noise_px, int num_pairs, unsigned seed, int cols = 7, int rows = 5) {
  Scene scene;
  scene.board.cols = cols;
  scene.board.rows = rows;
  scene.board.square_size_m = 0.04;
  scene.rig.cam0 = MakeCamera(238.0, 515.0, 381.0);
  scene.rig.cam1 = MakeCamera(241.0, 509.0, 386.0);
  scene.rig.cam0_from_cam1 = VerticalRig();
  std::mt19937 rng(seed);
  for (int i = 0; i < num_pairs; ++i) {
    const Rigid3d cam0_from_board =
        BoardPose(scene.board, 360.0 * i / num_pairs, 0.6 + 0.1 * (i % 4), 15.0 + 7.0 * (i % 3),
                  -0.05 + 0.02 * (i % 5));
    const Rigid3d cam1_from_board = scene.rig.cam0_from_cam1.Inverse() * cam0_from_board;
    StereoBoardPair pair;
    pair.name = "pair" + std::to_string(i);
    pair.cam0 = Detect(scene.rig.cam0, scene.board, cam0_from_board, noise_px, &rng);
    pair.cam1 = Detect(scene.rig.cam1, scene.board, cam1_from_board, noise_px, &rng);
    scene.pairs.push_back(pair);
  }
  return scene;
}

RelativePoseReport Estimate(const Scene& scene, const RelativePoseOptions& options = {}) {
  return EstimateRelativePose(scene.rig.cam0, scene.rig.cam1, scene.board, scene.pairs, options);
}

double RotationErrorDeg(const Rigid3d& a, const Rigid3d& b) {
  return RotationDistanceRad(a.rotation, b.rotation) * kDegPerRad;
}

TEST(RelposeLinear, ProjectToRotationIsNearestRotation) {
  const Eigen::Matrix3d truth =
      Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  EXPECT_LT((ProjectToRotation(truth) - truth).norm(), 1e-12);
  Eigen::Matrix3d noisy = truth;
  noisy(0, 1) += 0.01;
  noisy(2, 0) -= 0.02;
  const Eigen::Matrix3d projected = ProjectToRotation(noisy);
  EXPECT_LT((projected * projected.transpose() - Eigen::Matrix3d::Identity()).norm(), 1e-12);
  EXPECT_NEAR(projected.determinant(), 1.0, 1e-12);
  EXPECT_LT((projected - truth).norm(), 0.03);
  // A reflection is mapped to a proper rotation, not kept.
  EXPECT_NEAR(ProjectToRotation(-Eigen::Matrix3d::Identity()).determinant(), 1.0, 1e-12);
}

TEST(RelposeLinear, Eq9RecoversExactPoseAndRejectsCoplanarPoints) {
  const Rigid3d cam0_from_cam1 = VerticalRig();
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<Eigen::Vector3d> in_cam0, in_cam1, planar0, planar1;
  for (int i = 0; i < 40; ++i) {
    const Eigen::Vector3d p(u(rng), u(rng), u(rng));
    in_cam1.push_back(p);
    in_cam0.push_back(cam0_from_cam1 * p);
    const Eigen::Vector3d q(u(rng), u(rng), 0.5);
    planar1.push_back(q);
    planar0.push_back(cam0_from_cam1 * q);
  }
  const auto estimate = SolveRelativePoseLinear(in_cam0, in_cam1);
  ASSERT_TRUE(estimate.has_value());
  EXPECT_LT((estimate->translation - cam0_from_cam1.translation).norm(), 1e-12);
  EXPECT_LT(RotationErrorDeg(*estimate, cam0_from_cam1), 1e-9);
  EXPECT_FALSE(SolveRelativePoseLinear(planar0, planar1).has_value());
  EXPECT_LT(SpreadEigenRatio(planar1), 1e-12);
  EXPECT_GT(SpreadEigenRatio(in_cam1), 0.1);
}

TEST(RelposeLinear, AverageOfPosesIsTheirMean) {
  const Rigid3d base = VerticalRig();
  const Eigen::Quaterniond small(Eigen::AngleAxisd(0.01, Eigen::Vector3d::UnitX()));
  const Rigid3d a(base.rotation * small, base.translation + Eigen::Vector3d(0.001, 0, 0));
  const Rigid3d b(base.rotation * small.conjugate(), base.translation - Eigen::Vector3d(0.001, 0, 0));
  const Rigid3d mean = AverageRigidPoses({a, b});
  EXPECT_LT((mean.translation - base.translation).norm(), 1e-12);
  EXPECT_LT(RotationErrorDeg(mean, base), 1e-9);
}

TEST(RelposeCornerOrder, SymmetriesMapTheGridOntoItself) {
  BoardSpec board;
  board.cols = 4;
  board.rows = 4;
  board.square_size_m = 0.03;
  const auto symmetries = BoardGridSymmetries(board);
  ASSERT_EQ(symmetries.size(), 4u);  // identity, half turn, two quarter turns
  const auto points = board.ObjectPoints();
  for (const BoardSymmetry& symmetry : symmetries) {
    for (int id = 0; id < board.NumCorners(); ++id) {
      EXPECT_LT((symmetry.board_from_board * points[id] - points[symmetry.permutation[id]]).norm(),
                1e-12);
    }
  }
  board.cols = 5;
  EXPECT_EQ(BoardGridSymmetries(board).size(), 2u);
}

TEST(RelposeCost, Cam1ResidualIsTheProjectionThroughTheRig) {
  const Scene scene = MakeScene(0.0, 1, 1);
  const Rigid3d cam0_from_board = BoardPose(scene.board, 30.0, 0.7, 10.0, 0.0);
  const Eigen::Vector3d point = scene.board.ObjectPoints()[5];
  const Eigen::Vector2d observed(500.0, 300.0);
  std::unique_ptr<ceres::CostFunction> cost(RigCam1CornerCost::Create(observed, point));
  const auto board_params = cam0_from_board.ToParams();
  const auto rig_params = scene.rig.cam0_from_cam1.ToParams();
  const double* parameters[] = {board_params.data(), rig_params.data(),
                                scene.rig.cam1.intrinsics.params.data()};
  Eigen::Vector2d residual;
  ASSERT_TRUE(cost->Evaluate(parameters, residual.data(), nullptr));
  const auto expected = Project(scene.rig.cam1.intrinsics,
                                scene.rig.cam0_from_cam1.Inverse() * cam0_from_board * point);
  ASSERT_TRUE(expected.has_value());
  EXPECT_LT((residual - (*expected - observed)).norm(), 1e-9);
}

TEST(RelativePose, ExactCornersRecoverTheRig) {
  const Scene scene = MakeScene(0.0, 8, 1);
  const RelativePoseReport report = Estimate(scene);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_EQ(report.num_pairs_used, 8);
  EXPECT_LT((report.rig.cam0_from_cam1.translation - scene.rig.cam0_from_cam1.translation).norm(),
            1e-9);
  EXPECT_LT(RotationErrorDeg(report.rig.cam0_from_cam1, scene.rig.cam0_from_cam1), 1e-7);
  EXPECT_NEAR(report.baseline_m, scene.rig.cam0_from_cam1.translation.norm(), 1e-9);
  EXPECT_LT(report.rms_px, 1e-6);
  // The linear step alone is exact on exact corners too.
  EXPECT_LT((report.linear_cam0_from_cam1.translation - scene.rig.cam0_from_cam1.translation)
                .norm(),
            1e-7);
  for (const auto& pair : report.pairs) {
    EXPECT_TRUE(pair.used) << pair.reason;
    EXPECT_EQ(pair.cam1_order, 0);
    EXPECT_EQ(pair.num_corners, scene.board.NumCorners());
  }
}

// Across noisy trials, the scatter of the baseline error matches the reported standard
// deviation, and the refined rig beats the per-pair average.
TEST(RelativePose, NoiseGivesConsistentStandardDeviation) {
  const double noise_px = 0.3;
  const int num_trials = 12;
  double sum_sq_error = 0.0, sum_sq_std = 0.0, sum_sq_average_error = 0.0;
  for (int trial = 0; trial < num_trials; ++trial) {
    const Scene scene = MakeScene(noise_px, 10, 100 + trial);
    const RelativePoseReport report = Estimate(scene);
    ASSERT_TRUE(report.success) << report.message;
    // rms_px is the RMS of the Euclidean corner error: sigma * sqrt(2) for noise of sigma per
    // axis.
    EXPECT_NEAR(report.rms_px, noise_px * std::sqrt(2.0), 0.1 * noise_px);
    const double truth = scene.rig.cam0_from_cam1.translation.norm();
    sum_sq_error += std::pow(report.baseline_m - truth, 2);
    sum_sq_std += std::pow(report.baseline_std_m, 2);
    sum_sq_average_error += (report.averaged_cam0_from_cam1.translation -
                             scene.rig.cam0_from_cam1.translation).squaredNorm();
    EXPECT_GT(report.rotation_std_deg, 0.0);
    EXPECT_LT(RotationErrorDeg(report.rig.cam0_from_cam1, scene.rig.cam0_from_cam1),
              5.0 * report.rotation_std_deg);
  }
  const double empirical = std::sqrt(sum_sq_error / num_trials);
  const double predicted = std::sqrt(sum_sq_std / num_trials);
  EXPECT_GT(predicted, 1e-6);
  EXPECT_LT(predicted, 1e-3);
  EXPECT_GT(empirical / predicted, 0.5);
  EXPECT_LT(empirical / predicted, 2.0);
  EXPECT_LT(empirical, std::sqrt(sum_sq_average_error / num_trials));
}

TEST(RelativePose, HalfTurnedCornerOrdersAreResolved) {
  // 7 x 5 inner corners: 8 x 6 squares, a colouring symmetric under a half turn.
  Scene scene = MakeScene(0.1, 8, 7);
  HalfTurn(scene.board, &scene.pairs[1].cam1);
  HalfTurn(scene.board, &scene.pairs[4].cam1);
  HalfTurn(scene.board, &scene.pairs[6].cam0);  // cam0 flipped alone: cam1 must follow it
  const RelativePoseReport report = Estimate(scene);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_EQ(report.num_pairs_used, 8);
  EXPECT_EQ(report.pairs[0].cam1_order, 0);
  EXPECT_EQ(report.pairs[1].cam1_order, 1);
  EXPECT_EQ(report.pairs[4].cam1_order, 1);
  EXPECT_EQ(report.pairs[6].cam1_order, 1);
  EXPECT_LT(std::abs(report.baseline_m - scene.rig.cam0_from_cam1.translation.norm()), 5e-4);
  EXPECT_LT(report.rms_px, 0.2);

  RelativePoseOptions trusting;
  trusting.resolve_corner_order = false;
  const RelativePoseReport naive = Estimate(scene, trusting);
  EXPECT_LT(naive.num_pairs_used, 8);  // the flipped pairs disagree and are left out
}

TEST(RelativePose, QuarterTurnsOfSquareBoardsAreResolved) {
  Scene scene = MakeScene(0.0, 6, 9, 6, 6);
  for (int& id : scene.pairs[2].cam1.corner_ids) {
    const int r = id / 6, c = id % 6;
    id = (5 - c) * 6 + r;  // the inverse of a quarter turn
  }
  const RelativePoseReport report = Estimate(scene);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_EQ(report.num_pairs_used, 6);
  EXPECT_NE(report.pairs[2].cam1_order, 0);
  EXPECT_LT((report.rig.cam0_from_cam1.translation - scene.rig.cam0_from_cam1.translation).norm(),
            1e-9);
}

TEST(RelativePose, PairsSeenByOneCameraAreReportedUnused) {
  Scene scene = MakeScene(0.0, 6, 11);
  scene.pairs[2].cam1 = BoardDetection{};
  scene.pairs[2].cam1.reason = "no checkerboard";
  scene.pairs[3].cam0 = BoardDetection{};
  scene.pairs[3].cam0.reason = "too dark";
  const RelativePoseReport report = Estimate(scene);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_EQ(report.num_pairs_used, 4);
  EXPECT_FALSE(report.pairs[2].used);
  EXPECT_NE(report.pairs[2].reason.find("cam0 only"), std::string::npos) << report.pairs[2].reason;
  EXPECT_NE(report.pairs[2].reason.find("no checkerboard"), std::string::npos);
  EXPECT_NE(report.pairs[3].reason.find("cam1 only"), std::string::npos) << report.pairs[3].reason;
  EXPECT_LT((report.rig.cam0_from_cam1.translation - scene.rig.cam0_from_cam1.translation).norm(),
            1e-9);
}

TEST(RelativePose, BoardMovedBetweenExposuresIsLeftOut) {
  Scene scene = MakeScene(0.0, 6, 13);
  // cam1's image of pair 4 shows the board at another pose than cam0's.
  const Rigid3d elsewhere = BoardPose(scene.board, 100.0, 0.9, 30.0, 0.05);
  std::mt19937 rng(1);
  scene.pairs[4].cam1 = Detect(scene.rig.cam1, scene.board,
                               scene.rig.cam0_from_cam1.Inverse() * elsewhere, 0.0, &rng);
  ASSERT_TRUE(scene.pairs[4].cam1.found);
  const RelativePoseReport report = Estimate(scene);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_FALSE(report.pairs[4].used);
  EXPECT_NE(report.pairs[4].reason.find("disagrees"), std::string::npos);
  EXPECT_LT((report.rig.cam0_from_cam1.translation - scene.rig.cam0_from_cam1.translation).norm(),
            1e-9);
}

TEST(RelativePose, SlightlyMovedBoardIsRejectedByItsRms) {
  Scene scene = MakeScene(0.1, 8, 31);
  // Pair 3's board moved by 15 mm and 2 degrees between the two exposures: too little for the
  // consensus test, enough to spoil the joint fit.
  const Rigid3d cam0_from_board = BoardPose(scene.board, 360.0 * 3 / 8, 0.6 + 0.1 * 3,
                                            15.0 + 7.0 * 0, -0.05 + 0.02 * 3);
  const Rigid3d moved(
      Eigen::Quaterniond(Eigen::AngleAxisd(2.0 / kDegPerRad, Eigen::Vector3d::UnitZ())) *
          cam0_from_board.rotation,
      cam0_from_board.translation + Eigen::Vector3d(0.015, 0.0, 0.0));
  std::mt19937 rng(2);
  scene.pairs[3].cam1 =
      Detect(scene.rig.cam1, scene.board, scene.rig.cam0_from_cam1.Inverse() * moved, 0.1, &rng);
  const RelativePoseReport report = Estimate(scene);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_EQ(report.num_pairs_used, 7);
  EXPECT_FALSE(report.pairs[3].used);
  EXPECT_NE(report.pairs[3].reason.find("inconsistent"), std::string::npos)
      << report.pairs[3].reason;
  EXPECT_LT(report.rms_px, 0.2);
  EXPECT_LT(std::abs(report.baseline_m - scene.rig.cam0_from_cam1.translation.norm()), 3e-4);
}

// A pair whose board moved a little between the exposures: each camera alone fits it as well
// as any other pair, so only the comparison with those separate fits singles it out.
TEST(RelativePose, MovedBoardIsCaughtByTheSeparateFitsTest) {
  Scene scene = MakeScene(0.1, 6, 31);
  const Rigid3d cam0_from_board = BoardPose(scene.board, 360.0 * 3 / 6, 0.6 + 0.1 * 3,
                                            15.0 + 7.0 * 0, -0.05 + 0.02 * 3);
  const Rigid3d moved(cam0_from_board.rotation,
                      cam0_from_board.translation + Eigen::Vector3d(0.0, 0.0045, 0.0));
  std::mt19937 rng(2);
  scene.pairs[3].cam1 =
      Detect(scene.rig.cam1, scene.board, scene.rig.cam0_from_cam1.Inverse() * moved, 0.1, &rng);
  RelativePoseOptions options;
  options.min_rejected_pair_rms_px = 0.15;
  const RelativePoseReport median_only = Estimate(scene, options);
  ASSERT_TRUE(median_only.success) << median_only.message;
  ASSERT_TRUE(median_only.pairs[3].used) << median_only.pairs[3].reason;
  // Well over twice the 0.14 px that 0.1 px of noise per coordinate leaves in a separate fit.
  EXPECT_GT(median_only.pairs[3].rms_px, 0.3);
  options.max_pair_separate_ratio = 2.0;
  const RelativePoseReport report = Estimate(scene, options);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_EQ(report.num_pairs_used, 5);
  EXPECT_FALSE(report.pairs[3].used);
  EXPECT_NE(report.pairs[3].reason.find("fitting the board alone"), std::string::npos)
      << report.pairs[3].reason;
  EXPECT_LT(report.rms_px, 0.16);
  EXPECT_LT(std::abs(report.baseline_m - scene.rig.cam0_from_cam1.translation.norm()), 3e-4);
}

TEST(RelativePose, AllPairsAtOnePoseAreDegenerate) {
  Scene scene = MakeScene(0.2, 1, 17);
  std::mt19937 rng(5);
  const Rigid3d cam0_from_board = BoardPose(scene.board, 40.0, 0.7, 10.0, 0.0);
  scene.pairs.clear();
  for (int i = 0; i < 5; ++i) {
    StereoBoardPair pair;
    pair.name = "same" + std::to_string(i);
    pair.cam0 = Detect(scene.rig.cam0, scene.board, cam0_from_board, 0.2, &rng);
    pair.cam1 = Detect(scene.rig.cam1, scene.board,
                       scene.rig.cam0_from_cam1.Inverse() * cam0_from_board, 0.2, &rng);
    scene.pairs.push_back(pair);
  }
  const RelativePoseReport report = Estimate(scene);
  EXPECT_FALSE(report.success);
  EXPECT_TRUE(report.degenerate);
  EXPECT_NE(report.message.find("degenerate"), std::string::npos) << report.message;
}

TEST(RelativePose, TooFewPairsFailWithEachReason) {
  Scene scene = MakeScene(0.0, 3, 19);
  scene.pairs[0].cam1 = BoardDetection{};
  scene.pairs[0].cam1.reason = "blurred";
  scene.pairs[1].cam0 = BoardDetection{};
  scene.pairs[1].cam0.reason = "occluded";
  const RelativePoseReport report = Estimate(scene);
  EXPECT_FALSE(report.success);
  EXPECT_NE(report.message.find("too few usable pairs"), std::string::npos) << report.message;
  EXPECT_NE(report.message.find("blurred"), std::string::npos) << report.message;
  EXPECT_NE(report.message.find("occluded"), std::string::npos) << report.message;
}

TEST(RelativePose, RefiningIntrinsicsRecoversPerturbedCameras) {
  const Scene scene = MakeScene(0.0, 10, 23);
  CameraModel cam0 = scene.rig.cam0, cam1 = scene.rig.cam1;
  cam0.intrinsics.u0() += 1.5;
  cam1.intrinsics.gamma_v() *= 1.003;
  RelativePoseOptions options;
  options.refine_intrinsics = true;
  const RelativePoseReport report =
      EstimateRelativePose(cam0, cam1, scene.board, scene.pairs, options);
  ASSERT_TRUE(report.success) << report.message;
  EXPECT_LT(report.rms_px, 1e-4);
  EXPECT_LT((report.rig.cam0_from_cam1.translation - scene.rig.cam0_from_cam1.translation).norm(),
            1e-5);
  EXPECT_NEAR(report.rig.cam0.intrinsics.u0(), scene.rig.cam0.intrinsics.u0(), 1e-2);
}

TEST(RelativePose, FixedIntrinsicsKeepTheirValues) {
  const Scene scene = MakeScene(0.0, 5, 23);
  CameraModel cam0 = scene.rig.cam0, cam1 = scene.rig.cam1;
  cam0.intrinsics.u0() += 1.5;
  cam0.intrinsics.gamma_v() *= 1.003;
  cam0.intrinsics.params[UnifiedIntrinsics::kK5] = 1e-4;
  RelativePoseOptions options;
  options.refine_intrinsics = true;
  const RelativePoseReport by_default =
      EstimateRelativePose(cam0, cam1, scene.board, scene.pairs, options);
  ASSERT_TRUE(by_default.success) << by_default.message;
  EXPECT_EQ(by_default.rig.cam0.intrinsics.params[UnifiedIntrinsics::kK5], 1e-4);
  EXPECT_EQ(by_default.rig.cam0.intrinsics.params[UnifiedIntrinsics::kAlpha], 0.0);
  EXPECT_NE(by_default.rig.cam0.intrinsics.u0(), cam0.intrinsics.u0());
  options.fixed_intrinsics.fill(true);
  options.fixed_intrinsics[UnifiedIntrinsics::kU0] = false;
  const RelativePoseReport only_u0 =
      EstimateRelativePose(cam0, cam1, scene.board, scene.pairs, options);
  ASSERT_TRUE(only_u0.success) << only_u0.message;
  EXPECT_EQ(only_u0.rig.cam0.intrinsics.gamma_v(), cam0.intrinsics.gamma_v());
  for (int p = 0; p < UnifiedIntrinsics::kNumParams; ++p) {
    if (p == UnifiedIntrinsics::kU0) continue;  // free in both cameras
    EXPECT_EQ(only_u0.rig.cam1.intrinsics.params[p], cam1.intrinsics.params[p]) << p;
  }
  EXPECT_NE(only_u0.rig.cam0.intrinsics.u0(), cam0.intrinsics.u0());
}

TEST(RelativePose, InvalidOptionsAndCancellationThrow) {
  const Scene scene = MakeScene(0.0, 4, 29);
  RelativePoseOptions options;
  options.huber_loss_px = -1.0;
  EXPECT_THROW(Estimate(scene, options), InvalidArgument);
  options = RelativePoseOptions();
  options.max_pair_separate_ratio = 0.5;
  EXPECT_THROW(Estimate(scene, options), InvalidArgument);
  ProgressSink cancelled;
  cancelled.is_cancelled = [] { return true; };
  EXPECT_THROW(EstimateRelativePose(scene.rig.cam0, scene.rig.cam1, scene.board, scene.pairs, {},
                                    cancelled),
               Cancelled);
}

}  // namespace
}  // namespace omnirig
