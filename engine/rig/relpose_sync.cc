#include "engine/rig/relpose_sync.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>

#include <Eigen/Dense>

#include "engine/estimators/board_pose.h"
#include "engine/geometry/ceres_problem.h"
#include "engine/geometry/reprojection_cost.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {

double ChiSquareSurvival(double x, int dof) {
  OMNIRIG_CHECK(dof > 0 && dof % 2 == 0, "chi-square survival needs an even dof, got " << dof);
  if (x <= 0.0) return 1.0;
  // Q(x; 2m) = exp(-x/2) * sum_{k<m} (x/2)^k / k!: the Poisson tail's identity.
  const double half = 0.5 * x;
  double term = 1.0, sum = 1.0;
  for (int k = 1; k < dof / 2; ++k) {
    term *= half / k;
    sum += term;
  }
  return std::min(1.0, std::exp(-half) * sum);
}

double ChiSquareUpperQuantile(double p, int dof) {
  OMNIRIG_CHECK(p > 0.0 && p < 1.0, "probability must be in (0, 1), got " << p);
  double low = 0.0, high = dof + 10.0;
  while (ChiSquareSurvival(high, dof) > p) high *= 2.0;
  // Q decreases in x: bisection to machine precision.
  for (int i = 0; i < 200 && high - low > 1e-12 * high; ++i) {
    const double mid = 0.5 * (low + high);
    (ChiSquareSurvival(mid, dof) > p ? low : high) = mid;
  }
  return 0.5 * (low + high);
}

double ScaledFSurvival(double x, int dof, double denominator_dof) {
  OMNIRIG_CHECK(dof > 0 && dof % 2 == 0, "F survival needs an even numerator dof, got " << dof);
  OMNIRIG_CHECK(denominator_dof > 0.0, "F survival needs a positive denominator dof");
  if (x <= 0.0) return 1.0;
  // P(m F(m, n) > x) = I_z(n/2, m/2), z = n / (n + x), for even m a finite sum:
  // z^(n/2) sum_{j < m/2} Gamma(n/2 + j) / (Gamma(n/2) j!) (1 - z)^j.
  const double half_n = 0.5 * denominator_dof;
  const double z = denominator_dof / (denominator_dof + x);
  double term = 1.0, sum = 1.0;
  for (int j = 1; j < dof / 2; ++j) {
    term *= (half_n + j - 1.0) / j * (1.0 - z);
    sum += term;
  }
  return std::min(1.0, std::exp(half_n * std::log(z)) * sum);
}

double ScaledFUpperQuantile(double p, int dof, double denominator_dof) {
  OMNIRIG_CHECK(p > 0.0 && p < 1.0, "probability must be in (0, 1), got " << p);
  double low = 0.0, high = dof + 10.0;
  while (ScaledFSurvival(high, dof, denominator_dof) > p) high *= 2.0;
  for (int i = 0; i < 200 && high - low > 1e-12 * high; ++i) {
    const double mid = 0.5 * (low + high);
    (ScaledFSurvival(mid, dof, denominator_dof) > p ? low : high) = mid;
  }
  return 0.5 * (low + high);
}

void SyncTestOptions::Check() const {
  OMNIRIG_CHECK_IN(false_alarm_rate, '[', 0, 1, ')');
  OMNIRIG_CHECK_POSITIVE(min_corner_noise_px);
  OMNIRIG_CHECK_IN(max_rounds, '[', 1, 100, ']');
}

namespace {

constexpr int kPoseDof = 6;

double Median(std::vector<double> values) {
  const size_t mid = values.size() / 2;
  std::nth_element(values.begin(), values.begin() + mid, values.end());
  if (values.size() % 2 == 1) return values[mid];
  const double upper = values[mid];
  return 0.5 * (upper + *std::max_element(values.begin(), values.begin() + mid));
}

// One pair's two own board poses and their sums of squares (pixels^2).
struct SeparateFit {
  bool ok = false;
  std::optional<Rigid3d> cam_from_board[2];
  double sum_squares[2] = {0.0, 0.0};
  int dof[2] = {0, 0};
};

SeparateFit FitSeparately(const StereoRig& rig, const RigPairCorners& pair) {
  SeparateFit fit;
  double rms[2] = {0.0, 0.0};
  fit.cam_from_board[0] = EstimateBoardPose(rig.cam0, pair.points_in_board0, pair.pixels0, &rms[0]);
  fit.cam_from_board[1] = EstimateBoardPose(rig.cam1, pair.points_in_board1, pair.pixels1, &rms[1]);
  const size_t n[2] = {pair.pixels0.size(), pair.pixels1.size()};
  fit.ok = fit.cam_from_board[0] && fit.cam_from_board[1] && n[0] > 3 && n[1] > 3;
  for (int c = 0; c < 2; ++c) {
    // PoseRmsPx is sqrt(mean |e|^2) over corners: both coordinates' squares.
    fit.sum_squares[c] = rms[c] * rms[c] * static_cast<double>(n[c]);
    fit.dof[c] = 2 * static_cast<int>(n[c]) - kPoseDof;
  }
  return fit;
}

// Step 1 of the rule: sigma per camera from the separate fits.
std::array<double, 2> CornerNoise(const std::vector<SeparateFit>& fits,
                                  const SyncTestOptions& options) {
  std::array<double, 2> noise{};
  for (int c = 0; c < 2; ++c) {
    std::vector<double> variances, dofs;
    for (const SeparateFit& fit : fits) {
      if (!fit.ok) continue;
      variances.push_back(fit.sum_squares[c] / fit.dof[c]);
      dofs.push_back(fit.dof[c]);
    }
    double variance = 0.0;
    if (!variances.empty()) {
      int k = static_cast<int>(std::lround(Median(dofs)));
      k += k % 2;  // the closed form wants an even dof (2n - 6 always is)
      variance = Median(variances) / (ChiSquareUpperQuantile(0.5, k) / k);
    }
    noise[c] = std::max(options.min_corner_noise_px, std::sqrt(variance));
  }
  return noise;
}

// Step 2 for one pair: T (before the dispersion) and the disagreement in metric terms.
// `cam0_from_board`: the starting point of the fit through the rig; receives its solution.
PairSyncStatistic PairStatistic(const StereoRig& rig, const RigPairCorners& pair,
                                const SeparateFit& separate, const std::array<double, 2>& noise,
                                Rigid3d* cam0_from_board, double* raw_statistic) {
  PairSyncStatistic statistic;
  if (!separate.ok) return statistic;
  const double joint = FitBoardThroughRig(rig, pair, noise, cam0_from_board);
  if (joint < 0.0) return statistic;
  const double apart = separate.sum_squares[0] / (noise[0] * noise[0]) +
                       separate.sum_squares[1] / (noise[1] * noise[1]);
  // The separate fits are the unconstrained optimum: a negative difference is round-off.
  *raw_statistic = std::max(0.0, joint - apart);
  statistic.raw_statistic = *raw_statistic;
  for (int c = 0; c < 2; ++c) {
    statistic.own_dof[c] = separate.dof[c];
    statistic.own_variance_px2[c] = separate.sum_squares[c] / separate.dof[c];
  }
  const Rigid3d& own0 = *separate.cam_from_board[0];
  const Rigid3d via_cam1 = rig.cam0_from_cam1 * *separate.cam_from_board[1];
  const Eigen::Vector3d centre = RigPairBoardCentre(pair);
  statistic.board_offset_m = (own0 * centre - via_cam1 * centre).norm();
  statistic.board_rotation_deg =
      RotationDistanceRad(own0.rotation, via_cam1.rotation) * 180.0 / M_PI;
  statistic.valid = true;
  return statistic;
}

// A pair's fit through a rig, linearised at its solution: the residuals whitened by each
// camera's corner noise and their Jacobians with respect to the board pose's tangent (6) and
// the rig's free parameters (cam0_from_cam1's tangent, then cam0's and cam1's free
// intrinsics). No rows when a corner does not project.
struct PairLinearisation {
  Eigen::VectorXd residual;
  Eigen::MatrixXd board, rig;
  int rows0 = 0;  // cam0's rows come first
};

PairLinearisation Linearise(const StereoRig& rig, const RigPairCorners& pair,
                            const Rigid3d& cam0_from_board, const std::array<double, 2>& noise,
                            const HeldOutRigs& held_out) {
  const std::array<double, 7> board = cam0_from_board.ToParams();
  const std::array<double, 7> extrinsics = rig.cam0_from_cam1.ToParams();
  const std::unique_ptr<ceres::Manifold> pose(NewPoseManifold());
  Eigen::Matrix<double, 7, 6, Eigen::RowMajor> board_plus, rig_plus;
  pose->PlusJacobian(board.data(), board_plus.data());
  pose->PlusJacobian(extrinsics.data(), rig_plus.data());
  std::array<std::vector<int>, 2> free;
  for (int c = 0; c < 2; ++c) {
    for (int p = 0; p < UnifiedIntrinsics::kNumParams; ++p) {
      if (!held_out.fixed_intrinsics[c][p]) free[c].push_back(p);
    }
  }
  const int rows = 2 * static_cast<int>(pair.pixels0.size() + pair.pixels1.size());
  PairLinearisation linear;
  linear.residual.resize(rows);
  linear.board.setZero(rows, 6);
  linear.rig.setZero(rows, 6 + static_cast<int>(free[0].size() + free[1].size()));
  linear.rows0 = 2 * static_cast<int>(pair.pixels0.size());
  int row = 0;
  for (int c = 0; c < 2; ++c) {
    const auto& points = c == 0 ? pair.points_in_board0 : pair.points_in_board1;
    const auto& pixels = c == 0 ? pair.pixels0 : pair.pixels1;
    const double* intrinsics = (c == 0 ? rig.cam0 : rig.cam1).intrinsics.params.data();
    const int first_intrinsic = 6 + (c == 0 ? 0 : static_cast<int>(free[0].size()));
    for (size_t k = 0; k < pixels.size(); ++k, row += 2) {
      const std::unique_ptr<ReprojectionCost> cost(
          c == 0 ? ReprojectionCost::BoardCorner(points[k], pixels[k])
                 : ReprojectionCost::BoardCornerThroughRig(points[k], pixels[k]));
      Eigen::Matrix<double, 2, 7, Eigen::RowMajor> d_board, d_extrinsics;
      Eigen::Matrix<double, 2, UnifiedIntrinsics::kNumParams, Eigen::RowMajor> d_intrinsics;
      std::vector<const double*> blocks = {board.data()};
      std::vector<double*> jacobians = {d_board.data()};
      if (c == 1) {
        blocks.push_back(extrinsics.data());
        jacobians.push_back(d_extrinsics.data());
      }
      blocks.push_back(intrinsics);
      jacobians.push_back(d_intrinsics.data());
      Eigen::Vector2d residual;
      if (!cost->Evaluate(blocks.data(), residual.data(), jacobians.data())) return {};
      const double weight = 1.0 / noise[c];
      linear.residual.segment<2>(row) = weight * residual;
      linear.board.middleRows<2>(row) = weight * d_board * board_plus;
      if (c == 1) linear.rig.block<2, 6>(row, 0) = weight * d_extrinsics * rig_plus;
      for (size_t f = 0; f < free[c].size(); ++f) {
        linear.rig.col(first_intrinsic + f).segment<2>(row) = weight * d_intrinsics.col(free[c][f]);
      }
    }
  }
  return linear;
}

// What a held-out pair needs for its rig's prediction error (whitened units): its
// disagreement's coordinates along the 6 directions T measures (|z|^2 = T to first order),
// their sensitivity to the rig's parameters, and the pair's information on those parameters
// once its board pose is eliminated (what its own refit lacks).
struct PairLeverage {
  bool ok = false;
  Eigen::Matrix<double, 6, 1> disagreement;
  Eigen::MatrixXd sensitivity;  // 6 x rig parameters
  Eigen::MatrixXd information;  // rig parameters x rig parameters
};

PairLeverage LeverageOf(const PairLinearisation& linear) {
  PairLeverage leverage;
  const int rows = static_cast<int>(linear.residual.size()), rows1 = rows - linear.rows0;
  if (rows == 0) return leverage;
  // The separate fits move each camera's board pose alone (12 directions), the fit through the
  // rig both together (6 of those): T is the residuals' part along the 6 others.
  Eigen::MatrixXd separate = Eigen::MatrixXd::Zero(rows, 12);
  separate.topLeftCorner(linear.rows0, 6) = linear.board.topRows(linear.rows0);
  separate.bottomRightCorner(rows1, 6) = linear.board.bottomRows(rows1);
  const Eigen::HouseholderQR<Eigen::MatrixXd> joint(linear.board);
  const Eigen::MatrixXd joint_basis = joint.householderQ() * Eigen::MatrixXd::Identity(rows, 6);
  const Eigen::MatrixXd beyond = separate - joint_basis * (joint_basis.transpose() * separate);
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(beyond.transpose() * beyond);
  const Eigen::VectorXd& values = eigen.eigenvalues();  // ascending: 6 zeros, then the 6
  if (eigen.info() != Eigen::Success || !(values(6) > 1e-9 * values(11))) return leverage;
  Eigen::MatrixXd basis(rows, 6);
  for (int k = 0; k < 6; ++k) {
    basis.col(k) = beyond * eigen.eigenvectors().col(11 - k) / std::sqrt(values(11 - k));
  }
  leverage.disagreement = basis.transpose() * linear.residual;
  leverage.sensitivity = basis.transpose() * linear.rig;
  const Eigen::MatrixXd cross = linear.board.transpose() * linear.rig;
  leverage.information =
      linear.rig.transpose() * linear.rig -
      cross.transpose() * (linear.board.transpose() * linear.board).ldlt().solve(cross);
  leverage.ok = true;
  return leverage;
}

// A pair's T split along the directions of its disagreement, each with the variance that the
// reference rig's error adds along it (units of the corner noise's variance; 0 for a rig
// fitted with the pair): T / (w + beta) becomes sum_k share_k / (w + beta + added_k).
struct StatisticParts {
  std::array<double, 6> share{};
  std::array<double, 6> added{};
};

// The parts of each held-out pair: the rig fitted without pair i has the covariance (in
// whitened units) of the inverse of the other pairs' information, their sum less pair i's
// (each evaluated at its own held-out rig: rigs one pair apart). Its error moves the pair's
// disagreement by sensitivity * error: covariance S Sigma S^T, taken along its eigenvectors.
// A pair whose covariance cannot be formed keeps T whole.
void AddReferenceError(const std::vector<PairLeverage>& leverage, const std::vector<double>& raw,
                       std::vector<StatisticParts>* parts) {
  Eigen::MatrixXd total;
  for (const PairLeverage& pair : leverage) {
    if (!pair.ok) continue;
    total = total.size() == 0 ? pair.information : Eigen::MatrixXd(total + pair.information);
  }
  for (size_t i = 0; i < leverage.size(); ++i) {
    if (!leverage[i].ok) continue;
    const Eigen::LDLT<Eigen::MatrixXd> others(total - leverage[i].information);
    if (others.info() != Eigen::Success || !(others.vectorD().minCoeff() > 0.0)) continue;
    const Eigen::MatrixXd& sensitivity = leverage[i].sensitivity;
    const Eigen::Matrix<double, 6, 6> added = sensitivity * others.solve(sensitivity.transpose());
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 6, 6>> eigen(added);
    if (eigen.info() != Eigen::Success) continue;
    const Eigen::Matrix<double, 6, 1> along =
        eigen.eigenvectors().transpose() * leverage[i].disagreement;
    const double squared = along.squaredNorm();
    for (int k = 0; k < 6; ++k) {
      // The nonlinear T, shared out as its first-order form is.
      (*parts)[i].share[k] = squared > 0.0 ? raw[i] * along(k) * along(k) / squared : raw[i] / 6.0;
      (*parts)[i].added[k] = std::max(0.0, eigen.eigenvalues()(k));
    }
  }
}

// The noise a pair's T is judged by, against the rig's (sigma0, sigma1 per camera): its
// separate fits' whitened sum of squares per degree of freedom when that is above 1 (a pair
// noisier than most: farther, more oblique or more blurred on renders), else 1. Never below
// 1, because part of T does not shrink with the pair's own noise: the reference rig's error
// at the pair and the detector's errors common to all pairs (with w alone, clean pairs were
// flagged: bench_relpose --only sync, docs/relpose.md). Each camera's own variance is taken
// as at least min_noise_px^2 (exact synthetic corners).
double OwnNoiseRatio(const SeparateFit& fit, const std::array<double, 2>& noise,
                     double min_noise_px) {
  double whitened = 0.0;
  for (int c = 0; c < 2; ++c) {
    const double variance = std::max(fit.sum_squares[c] / fit.dof[c], min_noise_px * min_noise_px);
    whitened += variance * fit.dof[c] / (noise[c] * noise[c]);
  }
  return std::max(1.0, whitened / (fit.dof[0] + fit.dof[1]));
}

// x, a value of 6 F(6, dof), as the chi^2_6 value of the same tail probability: every
// pair's statistic on one scale, against one limit.
double OnChiSquareScale(double x, int dof) {
  constexpr double kSmallest = 1e-290;  // below it the order is kept by x itself
  const double p = ScaledFSurvival(x, kPoseDof, dof);
  if (p < kSmallest) return std::max(x, ChiSquareUpperQuantile(kSmallest, kPoseDof));
  return ChiSquareUpperQuantile(std::min(p, 1.0 - 1e-16), kPoseDof);
}

// T / (w + beta) with the reference rig's added variance: sum_k share_k / (w + beta + added_k).
double Whitened(const StatisticParts& parts, double scale, double beta) {
  double sum = 0.0;
  for (int k = 0; k < 6; ++k) sum += parts.share[k] / (scale + beta + parts.added[k]);
  return sum;
}

// Step 3's common extra variance beta (in units of the corner noise): the smallest beta >= 0
// with median T_i / (w_i + beta) at most `median_null`, the median of 6 F(6, dof).
double CommonExtraVariance(const std::vector<StatisticParts>& parts,
                           const std::vector<double>& scale, double median_null) {
  const auto excess = [&](double beta) {
    std::vector<double> ratios;
    for (size_t i = 0; i < parts.size(); ++i) ratios.push_back(Whitened(parts[i], scale[i], beta));
    return Median(ratios) - median_null;
  };
  if (excess(0.0) <= 0.0) return 0.0;
  double low = 0.0, high = 1.0;
  while (excess(high) > 0.0) high *= 2.0;
  for (int i = 0; i < 100 && high - low > 1e-9 * high; ++i) {
    const double mid = 0.5 * (low + high);
    (excess(mid) > 0.0 ? low : high) = mid;
  }
  return 0.5 * (low + high);
}

// Steps 3 and 4 (the dispersion and the decision) from each valid pair's T (`raw`, split in
// `parts`) and its separate fits.
void Decide(const std::vector<double>& raw, const std::vector<StatisticParts>& parts,
            const std::vector<SeparateFit>& separate, const SyncTestOptions& options,
            SyncTestReport* report) {
  std::vector<size_t> valid;
  std::vector<StatisticParts> valid_parts;
  std::vector<double> scale, whitened, dofs;
  for (size_t i = 0; i < raw.size(); ++i) {
    if (!report->pairs[i].valid) continue;
    valid.push_back(i);
    valid_parts.push_back(parts[i]);
    scale.push_back(
        OwnNoiseRatio(separate[i], report->corner_noise_px, options.min_corner_noise_px));
    whitened.push_back(raw[i] / scale.back());
    dofs.push_back(separate[i].dof[0] + separate[i].dof[1]);
  }
  report->median_statistic = Median(whitened);
  const double beta =
      CommonExtraVariance(valid_parts, scale, ScaledFUpperQuantile(0.5, kPoseDof, Median(dofs)));
  report->dispersion = 1.0 + beta;
  report->limit = ChiSquareUpperQuantile(options.false_alarm_rate / valid.size(), kPoseDof);
  for (size_t k = 0; k < valid.size(); ++k) {
    PairSyncStatistic& pair = report->pairs[valid[k]];
    double added = 0.0;
    for (double a : valid_parts[k].added) added += a / 6.0;
    pair.reference_variance = added;
    pair.statistic =
        OnChiSquareScale(Whitened(valid_parts[k], scale[k], beta), static_cast<int>(dofs[k]));
    pair.flagged = pair.statistic > report->limit;
    if (!pair.flagged) continue;
    ++report->num_flagged;
    if (report->worst < 0 || pair.statistic > report->pairs[report->worst].statistic) {
      report->worst = static_cast<int>(valid[k]);
    }
  }
}

}  // namespace

double SyncStatisticSurvival(double x) { return ChiSquareSurvival(x, kPoseDof); }

SyncTestReport TestPairSynchronisation(const StereoRig& rig,
                                       const std::vector<RigPairCorners>& pairs,
                                       const std::vector<Rigid3d>& cam0_from_board,
                                       const SyncTestOptions& options,
                                       const HeldOutRigs& held_out) {
  options.Check();
  OMNIRIG_CHECK(cam0_from_board.size() == pairs.size(), "one board pose per pair expected");
  const std::vector<StereoRig>& rig_of_pair = held_out.rig_of_pair;
  OMNIRIG_CHECK(rig_of_pair.empty() || rig_of_pair.size() == pairs.size(),
                "one rig per pair expected");
  SyncTestReport report;
  report.pairs.resize(pairs.size());
  if (pairs.size() < 3 || options.false_alarm_rate == 0.0) return report;
  std::vector<SeparateFit> separate;
  for (const RigPairCorners& pair : pairs) separate.push_back(FitSeparately(rig, pair));
  report.corner_noise_px = CornerNoise(separate, options);
  std::vector<double> raw(pairs.size(), 0.0);
  std::vector<PairLeverage> leverage(pairs.size());
  size_t num_valid = 0;
  for (size_t i = 0; i < pairs.size(); ++i) {
    const StereoRig& reference = rig_of_pair.empty() ? rig : rig_of_pair[i];
    if (!rig_of_pair.empty()) separate[i] = FitSeparately(reference, pairs[i]);
    Rigid3d joint_pose = cam0_from_board[i];
    report.pairs[i] = PairStatistic(reference, pairs[i], separate[i], report.corner_noise_px,
                                    &joint_pose, &raw[i]);
    num_valid += report.pairs[i].valid ? 1 : 0;
    if (!rig_of_pair.empty() && report.pairs[i].valid) {
      leverage[i] =
          LeverageOf(Linearise(reference, pairs[i], joint_pose, report.corner_noise_px, held_out));
    }
  }
  if (num_valid < 3) return report;
  report.run = true;
  std::vector<StatisticParts> parts(pairs.size());
  for (size_t i = 0; i < pairs.size(); ++i) parts[i].share[0] = raw[i];
  if (!rig_of_pair.empty()) AddReferenceError(leverage, raw, &parts);
  Decide(raw, parts, separate, options, &report);
  return report;
}

}  // namespace omnirig
