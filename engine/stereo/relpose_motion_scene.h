#pragma once
// Synthetic rigs like the real fisheye pairs of bench_relpose, with the board moved a little
// between the two exposures of every pair (for relpose_motion_test.cc and bench_relpose):
// 9 x 6 corners of 24.23 mm, boards 0.6-0.9 m away around the rig, 0.12 px of corner noise,
// and per pair a random rigid motion of the board (rotation about its centre, translation of
// the centre; isotropic Gaussian, std per axis).

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "engine/calib/calibrate.h"
#include "engine/stereo/relative_pose.h"
#include "engine/stereo/relpose_test_scene.h"

namespace omnirig {
namespace relpose_test {

struct MotionSceneOptions {
  int num_pairs = 24;
  double noise_px = 0.12;
  double rotation_std_deg = 0.0;   // per axis
  double translation_std_m = 0.0;  // per axis, of the board's centre
  // As the job does when it calibrates the cameras itself: each camera calibrated from its own
  // images of the pairs, then the intrinsics refined with the rig (default fixed set). Off:
  // the cameras are known.
  bool calibrate_cameras = false;
};

// Each camera of `scene` calibrated from its own images of the pairs (default options).
inline StereoRig CalibratedRig(const Scene& scene) {
  StereoRig rig = scene.rig;
  for (int camera = 0; camera < 2; ++camera) {
    std::vector<CalibrationView> views;
    for (const StereoBoardPair& pair : scene.pairs) {
      views.push_back({pair.name, camera == 0 ? pair.cam0 : pair.cam1});
    }
    CameraModel& model = camera == 0 ? rig.cam0 : rig.cam1;
    model = Calibrate(views, model.width, model.height, scene.board, CalibrationOptions(),
                      ProgressSink())
                .camera;
  }
  return rig;
}

// The board's centre in its own frame.
inline Eigen::Vector3d BoardCentreOf(const BoardSpec& board) {
  return Eigen::Vector3d(0.5 * (board.cols - 1) * board.square_size_m,
                         0.5 * (board.rows - 1) * board.square_size_m, 0.0);
}

// `cam0_from_board` moved by `rotation_vector` (cam0's frame) about the board's centre and by
// `shift` of the centre.
inline Rigid3d MoveBoard(const BoardSpec& board, const Rigid3d& cam0_from_board,
                         const Eigen::Vector3d& rotation_vector, const Eigen::Vector3d& shift) {
  const Eigen::Vector3d centre = cam0_from_board * BoardCentreOf(board);
  const double angle = rotation_vector.norm();
  const Eigen::Quaterniond rotation =
      angle > 0.0 ? Eigen::Quaterniond(Eigen::AngleAxisd(angle, rotation_vector / angle))
                  : Eigen::Quaterniond::Identity();
  const Rigid3d about_centre(rotation, centre + shift - rotation * centre);
  return about_centre * cam0_from_board;
}

// A seeded rig scene: the test scenes' cameras and vertical rig, the boards' poses and the
// motions drawn from `seed`.
inline Scene MakeMotionScene(const MotionSceneOptions& options, unsigned seed) {
  Scene scene;
  scene.board.cols = 9;
  scene.board.rows = 6;
  scene.board.square_size_m = 0.02423;
  scene.rig.cam0 = MakeCamera(238.0, 515.0, 381.0);
  scene.rig.cam1 = MakeCamera(241.0, 509.0, 386.0);
  scene.rig.cam0_from_cam1 = VerticalRig();
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::normal_distribution<double> normal(0.0, 1.0);
  const double azimuth0 = 360.0 * uniform(rng);
  for (int i = 0; i < options.num_pairs; ++i) {
    const Rigid3d cam0_from_board =
        BoardPose(scene.board, azimuth0 + 360.0 * i / options.num_pairs, 0.6 + 0.3 * uniform(rng),
                  10.0 + 20.0 * uniform(rng), -0.06 + 0.12 * uniform(rng));
    Eigen::Vector3d rotation_vector, shift;
    for (int k = 0; k < 3; ++k) {
      rotation_vector[k] = options.rotation_std_deg / kDegPerRad * normal(rng);
      shift[k] = options.translation_std_m * normal(rng);
    }
    const Rigid3d moved = MoveBoard(scene.board, cam0_from_board, rotation_vector, shift);
    StereoBoardPair pair;
    pair.name = "pair" + std::to_string(i);
    pair.cam0 = Detect(scene.rig.cam0, scene.board, cam0_from_board, options.noise_px, &rng);
    pair.cam1 = Detect(scene.rig.cam1, scene.board, scene.rig.cam0_from_cam1.Inverse() * moved,
                       options.noise_px, &rng);
    scene.pairs.push_back(pair);
  }
  return scene;
}

// One estimate's errors against the scene's truth.
struct RigErrors {
  bool ok = false;
  double baseline_error_m = 0.0;     // signed
  double translation_error_m = 0.0;  // |t - t_true|
  double rotation_error_deg = 0.0;
  double baseline_std_m = 0.0;  // as reported
  double baseline_std_robust_m = 0.0;  // the cluster-robust one
  bool motion_used = false;
  double motion_rotation_std_deg = 0.0;
  double motion_translation_std_m = 0.0;
  int num_pairs_used = 0;
};

inline RigErrors ErrorsOf(const Scene& scene, const RelativePoseReport& report) {
  RigErrors errors;
  errors.ok = report.success;
  if (!report.success) return errors;
  const Rigid3d& truth = scene.rig.cam0_from_cam1;
  errors.baseline_error_m = report.baseline_m - truth.translation.norm();
  errors.translation_error_m = (report.rig.cam0_from_cam1.translation - truth.translation).norm();
  errors.rotation_error_deg = RotationErrorDeg(report.rig.cam0_from_cam1, truth);
  errors.baseline_std_m = report.baseline_std_m;
  errors.baseline_std_robust_m = report.baseline_std_robust_m;
  errors.motion_used = report.board_motion.used;
  errors.motion_rotation_std_deg = report.board_motion.rotation_std_rad * kDegPerRad;
  errors.motion_translation_std_m = report.board_motion.translation_std_m;
  errors.num_pairs_used = report.num_pairs_used;
  return errors;
}

// Old (eq. 20) against new (board motion modelled) over seeds of one scene configuration.
struct MotionComparison {
  int num_seeds = 0;
  int failures = 0;
  double rms_baseline_error_m[2] = {0.0, 0.0};  // [old, new]
  double rms_translation_error_m[2] = {0.0, 0.0};
  double rms_rotation_error_deg[2] = {0.0, 0.0};
  double mean_baseline_std_m[2] = {0.0, 0.0};
  int covered[2] = {0, 0};                    // seeds with |baseline error| < 2 reported std
  int covered_robust[2] = {0, 0};             // the same with the cluster-robust std
  double mean_baseline_std_robust_m[2] = {0.0, 0.0};
  int motion_used = 0;                        // seeds where the new estimate used the model
  double mean_motion_rotation_std_deg = 0.0;  // over the seeds that used it
  double mean_motion_translation_std_m = 0.0;
  int identical = 0;  // seeds where new == old exactly (baseline and rotation)
};

inline MotionComparison CompareMotionModel(const MotionSceneOptions& scene_options, int num_seeds,
                                           unsigned first_seed) {
  MotionComparison result;
  RelativePoseOptions models[2];
  models[0].model_board_motion = false;
  models[1].model_board_motion = true;
  for (RelativePoseOptions& model : models) {
    model.refine_intrinsics = scene_options.calibrate_cameras;
  }
  for (int s = 0; s < num_seeds; ++s) {
    const Scene scene = MakeMotionScene(scene_options, first_seed + s);
    const StereoRig cameras = scene_options.calibrate_cameras ? CalibratedRig(scene) : scene.rig;
    RigErrors errors[2];
    RelativePoseReport reports[2];
    for (int m = 0; m < 2; ++m) {
      reports[m] =
          EstimateRelativePose(cameras.cam0, cameras.cam1, scene.board, scene.pairs, models[m]);
      errors[m] = ErrorsOf(scene, reports[m]);
    }
    if (!errors[0].ok || !errors[1].ok) {
      ++result.failures;
      continue;
    }
    ++result.num_seeds;
    for (int m = 0; m < 2; ++m) {
      result.rms_baseline_error_m[m] += errors[m].baseline_error_m * errors[m].baseline_error_m;
      result.rms_translation_error_m[m] +=
          errors[m].translation_error_m * errors[m].translation_error_m;
      result.rms_rotation_error_deg[m] +=
          errors[m].rotation_error_deg * errors[m].rotation_error_deg;
      result.mean_baseline_std_m[m] += errors[m].baseline_std_m;
      result.covered[m] += std::abs(errors[m].baseline_error_m) < 2.0 * errors[m].baseline_std_m;
      result.covered_robust[m] +=
          std::abs(errors[m].baseline_error_m) < 2.0 * errors[m].baseline_std_robust_m;
      result.mean_baseline_std_robust_m[m] += errors[m].baseline_std_robust_m;
    }
    if (errors[1].motion_used) {
      ++result.motion_used;
      result.mean_motion_rotation_std_deg += errors[1].motion_rotation_std_deg;
      result.mean_motion_translation_std_m += errors[1].motion_translation_std_m;
    }
    result.identical +=
        reports[0].rig.cam0_from_cam1.translation == reports[1].rig.cam0_from_cam1.translation &&
        reports[0].rig.cam0_from_cam1.rotation.coeffs() ==
            reports[1].rig.cam0_from_cam1.rotation.coeffs() &&
        reports[0].baseline_std_m == reports[1].baseline_std_m;
  }
  const double n = std::max(1, result.num_seeds);
  for (int m = 0; m < 2; ++m) {
    result.rms_baseline_error_m[m] = std::sqrt(result.rms_baseline_error_m[m] / n);
    result.rms_translation_error_m[m] = std::sqrt(result.rms_translation_error_m[m] / n);
    result.rms_rotation_error_deg[m] = std::sqrt(result.rms_rotation_error_deg[m] / n);
    result.mean_baseline_std_m[m] /= n;
    result.mean_baseline_std_robust_m[m] /= n;
  }
  if (result.motion_used > 0) {
    result.mean_motion_rotation_std_deg /= result.motion_used;
    result.mean_motion_translation_std_m /= result.motion_used;
  }
  return result;
}

}  // namespace relpose_test
}  // namespace omnirig
