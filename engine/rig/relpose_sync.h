#pragma once
// Were a pair's two images taken at the same instant? A statistical test of each board pair of
// a stereo rig against the corner noise: a pair whose board moved between two unsynchronised
// exposures cannot be fitted by any rig, and kept it biases the rig.
//
// The rule (fixed from first principles before it was run on real pairs; checked on synthetic
// pairs with boards moved by 1-3 mm between the two shots in relpose_sync_test.cc):
//   1. Corner noise. Each camera fits the pair's board alone (pose-only least squares, camera
//      fixed): sums of squares S0, S1 on 2 n0 - 6 and 2 n1 - 6 degrees of freedom (n corners).
//      These fits do not depend on the exposures being simultaneous, so they measure the noise
//      alone. Per camera, sigma^2 = the median over the pairs of S / (2n - 6), divided by the
//      median of chi^2_k / k (k: the median degrees of freedom) so that it estimates the
//      variance; never below min_corner_noise_px^2 (exact synthetic corners).
//   2. Statistic. The pair's board fitted once through the rig (one board pose for both
//      images, rig and cameras fixed), each camera's residuals divided by its sigma: sum of
//      squares J. T = J - S0 / sigma0^2 - S1 / sigma1^2 is the likelihood ratio of one board
//      pose against two; with simultaneous exposures and independent Gaussian corner noise of
//      sigma0, sigma1 it follows chi^2 with 6 degrees of freedom (a little less, as the rig was
//      fitted with the pair). But the noise differs from pair to pair (on renders the pairs'
//      own-fit variances span a factor of 6: board distance, obliquity, blur), and a pair
//      noisier than the median had T ~ (sigma_i / sigma)^2 chi^2_6: the test's false alarms on
//      synchronised renders were far above its rate. So each pair is judged by its own noise,
//      as in Chow's test of one regression against two: w = (S0 / sigma0^2 + S1 / sigma1^2) /
//      (dof0 + dof1), and T / w follows 6 F(6, dof0 + dof1) (the noise is estimated from the
//      same pair's fits, independent of T). w is taken as at least 1: part of T does not shrink
//      with the pair's own noise (the reference rig's error at the pair, detector errors
//      common to all pairs), and with w alone the cleanest pairs were flagged instead.
//      When the reference is a rig fitted without the pair (HeldOutRigs: the cameras kept at
//      their own calibrations), that rig's error at the pair is predicted too: the other
//      pairs' Gauss-Newton covariance of its parameters carried to the pair's 6 directions of
//      disagreement (S Sigma S^T, in units of the corner noise), added along its eigenvectors.
//      A pair alone in its part of the mirror is predicted worst by the others: on synchronised
//      renders the two pairs the test lost had 2.8 and 6.5 times the corner noise's variance
//      there, against a median of 0.16 (bench_relpose --only sync, docs/relpose.md).
//   3. Dispersion. Corner errors that are not independent (correlated along a board's edges,
//      a model error every view shares, the reference rig's own error) add to every pair's T
//      a part that does not scale with the pair's own noise; an unsynchronised pair stands
//      out from the others. As in a random-effects model, each pair's T is judged against
//      w + beta, beta >= 0 the smallest common extra variance (in units of the corner noise)
//      that brings the median of T / (w + beta) down to the median of 6 F(6, dof); the report's
//      dispersion is 1 + beta (kappa: with every w = 1, T / kappa). So at most half the pairs
//      can be flagged, whatever the noise. On renders beta is about 0 and w decides; on the real
//      fisheye pairs of bench_relpose kappa is about 25 (even the pairs kept disagree far more
//      than independent corner noise of the mono fits' 0.12 px would explain) and beta
//      decides. Each pair's statistic is T / (w + beta) expressed on the chi^2_6 scale (the
//      chi^2_6 value of the same tail probability under 6 F(6, dof)), so that one limit serves
//      every pair.
//   4. Decision, one pair at a time. The pair with the largest statistic is unsynchronised
//      when that exceeds the chi^2_6 quantile at 1 - alpha / N (N pairs tested, alpha the
//      family-wise false-alarm rate, 1 % by default). The caller (EstimateRelativePose) leaves
//      it out, refits the rig and tests the N - 1 others again, until the largest is below the
//      limit. Holm's step-down: with simultaneous pairs only the first test can reject, at
//      alpha / N for the largest of N, so a set of simultaneous pairs loses one or more with
//      probability at most alpha. One at a time because a pair that moved a lot pulls the rig
//      and with it the statistics of the others (a 15 mm move in relative_pose_test.cc pushes
//      a simultaneous pair over the limit until the rig is refitted without it). At most half
//      the pairs first used are left out: the test assumes that most are simultaneous.
//      On synthetic rigs like the real fisheye pairs (9 x 6 corners, 0.12 px per coordinate,
//      boards 0.6-0.9 m away) this flags a 2-3 mm move in every trial and a 1 mm move in most
//      (relpose_sync_power_test.cc measures it).
// The disagreement reported in millimetres is the board's centre in cam0 from cam0's own fit
// against cam1's own fit mapped through the rig. It is for the user: it includes the two own
// fits' noise (mostly along the line of sight: about 1 mm for the synthetic rigs above), which
// the statistic accounts for and a distance in millimetres cannot.

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
