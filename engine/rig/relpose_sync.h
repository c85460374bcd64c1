#pragma once
// Were a pair's two images taken at the same instant? A statistical test of each board pair of
// a stereo rig against the corner noise: a pair whose board moved between two unsynchronised
// exposures cannot be fitted by any rig, and kept it biases the rig. Each pair's likelihood
// ratio of one board pose against two (Chow's test), judged against its own corner noise and
// the pairs' common dispersion, is compared with the chi^2_6 quantile at 1 - alpha / N, one
// pair at a time (Holm's step-down). The rule, why it is built so, and its measured power:
// docs/relpose.md, "The synchronisation test".

#include <array>
#include <vector>

#include "engine/geometry/camera_model.h"
#include "engine/geometry/rigid3.h"
#include "engine/rig/relpose_refine.h"

namespace omnirig {

// P(X > x) for X ~ chi^2 with `dof` degrees of freedom; dof even and positive (closed form).
double ChiSquareSurvival(double x, int dof);

// The x with ChiSquareSurvival(x, dof) = p, for p in (0, 1); dof even and positive.
double ChiSquareUpperQuantile(double p, int dof);

// P(X > x) for X = dof * F(dof, denominator_dof): a chi^2_dof variable divided by an
// independent variance estimate on denominator_dof degrees of freedom (it tends to
// ChiSquareSurvival as denominator_dof grows). dof even and positive (closed form).
double ScaledFSurvival(double x, int dof, double denominator_dof);

// The x with ScaledFSurvival(x, dof, denominator_dof) = p, for p in (0, 1).
double ScaledFUpperQuantile(double p, int dof, double denominator_dof);

struct SyncTestOptions {
  // alpha: the probability that a set of simultaneous pairs loses one or more to the test.
  // 0 turns the test off.
  double false_alarm_rate = 0.01;
  // The corner noise (per coordinate) is never assumed below this.
  double min_corner_noise_px = 0.01;
  // Test, leave out the worst pair, refit: at most this many rounds (and never more than half
  // the pairs first used).
  int max_rounds = 20;

  // Throws InvalidArgument naming the offending field.
  void Check() const;
};

struct PairSyncStatistic {
  bool valid = false;  // false when a camera's own board pose or the rig fit failed
  // T / (w + beta) on the chi^2_6 scale (the rule's step 3), compared with the limit.
  double statistic = 0.0;
  double raw_statistic = 0.0;  // T, before the pair's own noise and the dispersion
  // Each camera's own fit of the board: sum of squares / degrees of freedom (px^2), and dof.
  std::array<double, 2> own_variance_px2{};
  std::array<int, 2> own_dof{};
  // With held-out rigs: that rig's prediction error at the pair, the variance it adds to the
  // pair's disagreement (mean over its 6 directions, in units of the corner noise's); else 0.
  double reference_variance = 0.0;
  bool flagged = false;  // statistic over the limit (only the worst is left out per round)
  // cam0's own board pose against cam1's own through the rig, at the board's centre.
  double board_offset_m = 0.0;
  double board_rotation_deg = 0.0;
};

struct SyncTestReport {
  bool run = false;                         // false with fewer than 3 pairs
  std::array<double, 2> corner_noise_px{};  // sigma per coordinate, cam0 and cam1
  double dispersion = 1.0;                  // kappa = 1 + beta
  double limit = 0.0;                       // chi^2_6 quantile at 1 - alpha / N
  double median_statistic = 0.0;            // median T / w (before the dispersion)
  int num_flagged = 0;
  int worst = -1;                        // the flagged pair with the largest statistic
  std::vector<PairSyncStatistic> pairs;  // one per tested pair
};

// P(statistic > x) under the null hypothesis (simultaneous exposures) that
// SyncTestReport::limit is the quantile of: the per-pair p-value of a
// PairSyncStatistic::statistic.
double SyncStatisticSurvival(double x);

// The rigs the pairs are judged by when each was refitted without its pair (relative_pose.cc,
// SyncTestRigs): cam0_from_cam1 and the intrinsics but `fixed_intrinsics` (per camera,
// UnifiedIntrinsics order) fitted to the other pairs.
struct HeldOutRigs {
  std::vector<StereoRig> rig_of_pair;  // one per pair
  std::array<std::array<bool, UnifiedIntrinsics::kNumParams>, 2> fixed_intrinsics{};
};

// Tests every pair of a fitted rig. `cam0_from_board`: the joint fit's board poses (starting
// points of the fits through the rig). With `held_out` rigs, pair i is judged by its own rig
// instead (its separate fits and the fit through the rig use that rig's cameras), and its
// disagreement is expected to include that rig's prediction error at the pair (the rig fitted
// to the other pairs, their Gauss-Newton covariance carried to the pair: J Sigma J^T); the
// corner noise still comes from `rig`'s. Needs at least 3 pairs (else report.run is false).
SyncTestReport TestPairSynchronisation(const StereoRig& rig,
                                       const std::vector<RigPairCorners>& pairs,
                                       const std::vector<Rigid3d>& cam0_from_board,
                                       const SyncTestOptions& options,
                                       const HeldOutRigs& held_out = {});

}  // namespace omnirig
