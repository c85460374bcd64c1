#pragma once
// The board's motion between the two exposures of a pair, as a random effect of the stereo
// rig's joint refinement.
//
// With unsynchronised exposures a handheld board moves a little between cam0's and cam1's
// shot. The synchronisation test (relpose_sync.h) leaves out the pairs that moved grossly; the
// others still disagree by more than the corner noise explains (on the real fisheye pairs of
// bench_relpose by about 25 times, in chi^2 units). Eq. 20 treats that disagreement as
// impossible: it weights pairs by their corners' precision (close boards dominate) and reports
// a covariance from corner noise alone, far too small. The model here: per used pair i,
// cam1 sees the board at cam1_from_cam0 * cam0_from_board_i * Delta_i with
// Delta_i ~ N(0, Sigma), Sigma isotropic per part: sigma_r^2 per axis of the rotation vector,
// sigma_t^2 per axis of the board centre's displacement. In the refinement each pair gets cam1's
// own board pose, linked to the rig's prediction by BoardMotionLinkCost (6 whitened residuals):
// the Gauss-Newton covariance then marginalises the motion, and the weights become the
// generalised least squares ones (corner covariance + Sigma).
//
// The rule (written before it was run on the real pairs, and not changed after):
//   1. Input: the rig fitted by eq. 20 on the pairs the synchronisation test kept, and the
//      corner noise per camera that test estimated (sigma0, sigma1: px per coordinate).
//   2. Per pair, each camera's own board pose (pose-only fit, camera fixed) and its covariance
//      sigma_c^2 (J^T J)^-1, J the corners' pixels against a perturbation of the pose by a
//      rotation about the board's centre and a translation of that centre (camera frame).
//      The disagreement delta_i = (omega_i, d_i) in cam0's frame: the rotation vector from
//      cam0's own pose to cam1's own pose mapped through the rig, and the displacement of the
//      board's centre between them (what the synchronisation test reports). Its covariance
//      from the corner noise C_i = C0_i + R C1_i R^T (R: the rig's rotation on both parts).
//   3. Method of moments, per part, over the N pairs:
//        sigma_r^2 = max(0, sum_i (|omega_i|^2 - trace C_i^omega)) / (3 (N - 1)),
//        sigma_t^2 = max(0, sum_i (|d_i|^2 - trace C_i^d)) / (3 (N - 1)),
//      N - 1 because the rig is fitted to the same pairs (it absorbs the disagreements' mean).
//   4. Significance: S = sum_i delta_i^T C_i^-1 delta_i, which without motion follows about
//      chi^2 with 6 (N - 1) degrees of freedom. The model is used only when S exceeds that
//      distribution's 1 - alpha quantile (alpha = 1 % by default), at least 3 pairs are used,
//      and at least one part's estimate is positive. Otherwise the refinement is exactly eq.
//      20 (no extra blocks, no link cost): clean rigs are fitted as before.
//   5. Each part's std is floored at min_std_fraction (10 %) of the corner noise's own RMS
//      std of that part (sqrt of the mean trace C_i / 3): a part whose estimate clamped to 0
//      while the other did not becomes a near-hard constraint that stays well conditioned.
//   6. One pass: Sigma from the eq.-20 rig, then the rig refitted with the prior (warm start),
//      and its covariance (EstimateRigUncertainty with the prior) is reported. Sigma is not
//      re-estimated from the new rig.
// Order with the synchronisation test: that test runs first, as it was, with its robust
// dispersion (median-based: the gross movers cannot inflate it), and Sigma is estimated only
// from the pairs it keeps. Estimating Sigma first, by moments, would let a gross mover inflate
// Sigma and hide itself. The test is not rerun against C_i + Sigma afterwards: its dispersion
// already scales the corner covariance to the kept pairs' spread, and a second pass with
// Sigma would test the pairs against a spread estimated from themselves (circular).
// (A remaining asymmetry: the test's kappa C_i scales with each pair's precision, C_i + Sigma
// does not, so close boards are flagged a little more readily than the motion model implies.)
//
// Frames and units: radians and metres, per axis; cam0_from_cam1 as in relative_pose.h.

#include <array>
#include <vector>

#include <ceres/cost_function.h>
#include <ceres/rotation.h>
#include <Eigen/Core>
#include <Eigen/Geometry>

#include "engine/geometry/camera_model.h"
#include "engine/geometry/rigid3.h"
#include "engine/stereo/relpose_refine.h"

namespace omnirig {

struct BoardMotionOptions {
  // alpha of step 4: the probability of using the model on a rig without motion.
  double significance = 0.01;
  // Step 5's floor, as a fraction of the corner noise's std of the part.
  double min_std_fraction = 0.1;

  // Throws InvalidArgument naming the offending field.
  void Check() const;
};

struct BoardMotionEstimate {
  bool used = false;  // steps 4-5 passed: the refinement takes the prior
  int num_pairs = 0;  // pairs with both own fits (N)
  // Steps 3 and 5 (per axis); the moment estimates before the floor are in raw_*.
  double rotation_std_rad = 0.0;
  double translation_std_m = 0.0;
  double raw_rotation_std_rad = 0.0;
  double raw_translation_std_m = 0.0;
  // The corner noise's part, per axis: sqrt(mean_i trace C_i^part / 3).
  double noise_rotation_std_rad = 0.0;
  double noise_translation_std_m = 0.0;
  // Step 4.
  double statistic = 0.0;
  int dof = 0;
  double limit = 0.0;
  // The corner noise per camera (px per coordinate) the estimate was made with: with the
  // standard deviations, what ToBoardMotionPrior needs to rebuild the prior (e.g. for the
  // cross-validation folds of relpose_model_select.h).
  std::array<double, 2> corner_noise_px = {0.0, 0.0};
};

// Steps 2-5 of the rule, on the pairs of a rig fitted by eq. 20. `corner_noise_px`: per
// camera (the synchronisation test's). Pairs whose own fits fail are left out of the moments.
BoardMotionEstimate EstimateBoardMotion(const StereoRig& rig,
                                        const std::vector<RigPairCorners>& pairs,
                                        const std::array<double, 2>& corner_noise_px,
                                        const BoardMotionOptions& options);

// The refinement's prior from an estimate used by the rule: the standard deviations, and the
// pooled corner noise sqrt((sigma0^2 + sigma1^2) / 2) that scales the link residuals.
BoardMotionPrior ToBoardMotionPrior(const BoardMotionEstimate& estimate,
                                    const std::array<double, 2>& corner_noise_px);

// The link between cam0's board pose, the rig, and cam1's own board pose of one pair:
// delta = (rotation vector of via1 * own0^-1, via1 * c - own0 * c) in cam0's frame, where
// via1 = cam0_from_cam1 * cam1_from_board, own0 = cam0_from_board, c the board's centre;
// residual = (w_r omega, w_t d) with w = corner_noise_px / sigma (whitened, in pixel units).
// Parameter blocks (7 each, Rigid3d::ToParams order): cam0_from_board, cam0_from_cam1,
// cam1_from_board.
struct BoardMotionLinkCost {
  BoardMotionLinkCost(const Eigen::Vector3d& centre_in_board, double rotation_weight,
                      double translation_weight)
      : centre(centre_in_board),
        rotation_weight(rotation_weight),
        translation_weight(translation_weight) {}

  template <typename T>
  bool operator()(const T* cam0_from_board, const T* cam0_from_cam1, const T* cam1_from_board,
                  T* residual) const {
    using Quaternion = Eigen::Quaternion<T>;
    using Vector3 = Eigen::Matrix<T, 3, 1>;
    const Eigen::Map<const Quaternion> q_board(cam0_from_board);
    const Eigen::Map<const Vector3> t_board(cam0_from_board + 4);
    const Eigen::Map<const Quaternion> q_rig(cam0_from_cam1);
    const Eigen::Map<const Vector3> t_rig(cam0_from_cam1 + 4);
    const Eigen::Map<const Quaternion> q_cam1(cam1_from_board);
    const Eigen::Map<const Vector3> t_cam1(cam1_from_board + 4);
    const Quaternion q_via = q_rig * q_cam1;
    const Vector3 t_via = q_rig * t_cam1 + t_rig;
    const Quaternion q_delta = q_via * q_board.conjugate();
    const T wxyz[4] = {q_delta.w(), q_delta.x(), q_delta.y(), q_delta.z()};
    T omega[3];
    ceres::QuaternionToAngleAxis(wxyz, omega);
    const Vector3 c = centre.cast<T>();
    const Vector3 d = (q_via * c + t_via) - (q_board * c + t_board);
    for (int k = 0; k < 3; ++k) {
      residual[k] = T(rotation_weight) * omega[k];
      residual[3 + k] = T(translation_weight) * d[k];
    }
    return true;
  }

  static ceres::CostFunction* Create(const Eigen::Vector3d& centre_in_board,
                                     const BoardMotionPrior& prior);

  Eigen::Vector3d centre;
  double rotation_weight;
  double translation_weight;
};

}  // namespace omnirig
