#include "engine/rig/relpose_refine.h"

#include <cmath>
#include <memory>
#include <optional>

#include <ceres/ceres.h>

#include "engine/geometry/ceres_problem.h"
#include "engine/geometry/reprojection_cost.h"

namespace omnirig {

std::array<bool, UnifiedIntrinsics::kNumParams> DefaultFixedIntrinsics() {
  std::array<bool, UnifiedIntrinsics::kNumParams> fixed{};
  fixed[UnifiedIntrinsics::kAlpha] = true;
  fixed[UnifiedIntrinsics::kK5] = true;
  return fixed;
}

namespace {

struct RigBlocks {
  std::array<double, 7> cam0_from_cam1;
  std::vector<std::array<double, 7>> cam0_from_board;
  std::array<double, UnifiedIntrinsics::kNumParams> intrinsics0, intrinsics1;
};

RigBlocks BlocksOf(const StereoRig& rig, const std::vector<Rigid3d>& cam0_from_board) {
  RigBlocks blocks;
  blocks.cam0_from_cam1 = rig.cam0_from_cam1.ToParams();
  for (const Rigid3d& pose : cam0_from_board) blocks.cam0_from_board.push_back(pose.ToParams());
  blocks.intrinsics0 = rig.cam0.intrinsics.params;
  blocks.intrinsics1 = rig.cam1.intrinsics.params;
  return blocks;
}

// `pair_residuals`, when given, receives each pair's residual blocks (for the robust covariance).
void AddResiduals(const std::vector<RigPairCorners>& pairs, const RigRefinementOptions& options,
                  RigBlocks* blocks, ceres::Problem* problem,
                  std::vector<std::vector<ceres::ResidualBlockId>>* pair_residuals = nullptr) {
  if (pair_residuals != nullptr) pair_residuals->assign(pairs.size(), {});
  const auto keep = [pair_residuals](size_t i, ceres::ResidualBlockId id) {
    if (pair_residuals != nullptr) (*pair_residuals)[i].push_back(id);
  };
  ceres::LossFunction* loss = options.huber_loss_px > 0.0
                                  ? new ceres::HuberLoss(options.huber_loss_px)
                                  : nullptr;
  for (size_t i = 0; i < pairs.size(); ++i) {
    double* board = blocks->cam0_from_board[i].data();
    for (size_t c = 0; c < pairs[i].pixels0.size(); ++c) {
      keep(i, problem->AddResidualBlock(
                  ReprojectionCost::BoardCorner(pairs[i].points_in_board0[c], pairs[i].pixels0[c]),
                  loss, board, blocks->intrinsics0.data()));
    }
    for (size_t c = 0; c < pairs[i].pixels1.size(); ++c) {
      keep(i, problem->AddResidualBlock(
                  ReprojectionCost::BoardCornerThroughRig(pairs[i].points_in_board1[c],
                                                          pairs[i].pixels1[c]),
                  loss, board, blocks->cam0_from_cam1.data(), blocks->intrinsics1.data()));
    }
    problem->SetManifold(board, NewPoseManifold());
  }
  problem->SetManifold(blocks->cam0_from_cam1.data(), NewPoseManifold());
  for (int camera = 0; camera < 2; ++camera) {
    const auto& fixed_set = camera == 1 && options.cam1_fixed_intrinsics
                                ? *options.cam1_fixed_intrinsics
                                : options.fixed_intrinsics;
    double* intrinsics = camera == 0 ? blocks->intrinsics0.data() : blocks->intrinsics1.data();
    std::vector<int> fixed;
    for (int p = 0; p < UnifiedIntrinsics::kNumParams; ++p) {
      if (fixed_set[p]) fixed.push_back(p);
    }
    if (!options.refine_intrinsics || fixed.size() == UnifiedIntrinsics::kNumParams) {
      problem->SetParameterBlockConstant(intrinsics);
    } else if (!fixed.empty()) {
      problem->SetManifold(intrinsics,
                           new ceres::SubsetManifold(UnifiedIntrinsics::kNumParams, fixed));
    }
  }
}

double SumSquaredResiduals(ceres::Problem* problem, int* num_residuals) {
  ceres::Problem::EvaluateOptions evaluate;
  evaluate.apply_loss_function = false;
  std::vector<double> residuals;
  problem->Evaluate(evaluate, nullptr, &residuals, nullptr, nullptr);
  double sum = 0.0;
  for (double r : residuals) sum += r * r;
  *num_residuals = static_cast<int>(residuals.size());
  return sum;
}

int NumFreeParameters(const ceres::Problem& problem) {
  std::vector<double*> blocks;
  problem.GetParameterBlocks(&blocks);
  int count = 0;
  for (double* block : blocks) {
    if (!problem.IsParameterBlockConstant(block)) count += problem.ParameterBlockTangentSize(block);
  }
  return count;
}

using Matrix6d = Eigen::Matrix<double, 6, 6>;

struct RigStd {
  Eigen::Vector3d translation_m = Eigen::Vector3d::Zero();
  double baseline_m = 0.0;
  double rotation_deg = 0.0;
};

// The standard deviations of a covariance of cam0_from_cam1's tangent (rotation, translation).
RigStd StdOfTangentCovariance(const Matrix6d& covariance, const double* rig) {
  // EigenQuaternionManifold's tangent d rotates by exp(d) as a quaternion: an angle of 2|d|.
  const Eigen::Matrix3d rotation_cov = 4.0 * covariance.topLeftCorner<3, 3>();
  const Eigen::Matrix3d translation_cov = covariance.bottomRightCorner<3, 3>();
  const Eigen::Vector3d t(rig[4], rig[5], rig[6]);
  const Eigen::Vector3d direction = t.norm() > 0 ? Eigen::Vector3d(t.normalized())
                                                 : Eigen::Vector3d::UnitX();
  RigStd std;
  std.translation_m = translation_cov.diagonal().cwiseMax(0.0).cwiseSqrt();
  std.baseline_m = std::sqrt(std::max(0.0, direction.dot(translation_cov * direction)));
  std.rotation_deg = std::sqrt(std::max(0.0, rotation_cov.trace())) * 180.0 / M_PI;
  return std;
}

// The cluster-robust covariance of the rig's tangent (RigUncertainty states the formula), from
// the Jacobian and residuals (with the robust loss's correction) at the solution. The rig's
// block comes first among the free parameters, so only its 6 rows of H^-1 G are needed.
std::optional<Matrix6d> ClusteredRigCovariance(
    ceres::Problem* problem, double* rig,
    const std::vector<std::vector<ceres::ResidualBlockId>>& pair_residuals) {
  const int num_pairs = static_cast<int>(pair_residuals.size());
  if (num_pairs < 3 || problem->IsParameterBlockConstant(rig)) return std::nullopt;
  ceres::Problem::EvaluateOptions evaluate;
  std::vector<double*> all_blocks;
  problem->GetParameterBlocks(&all_blocks);
  evaluate.parameter_blocks.push_back(rig);
  for (double* block : all_blocks) {
    if (block != rig && !problem->IsParameterBlockConstant(block)) {
      evaluate.parameter_blocks.push_back(block);
    }
  }
  std::vector<int> row_pair;  // the pair of each residual row
  for (int i = 0; i < num_pairs; ++i) {
    for (const ceres::ResidualBlockId id : pair_residuals[i]) {
      evaluate.residual_blocks.push_back(id);
      const int rows = problem->GetCostFunctionForResidualBlock(id)->num_residuals();
      row_pair.insert(row_pair.end(), rows, i);
    }
  }
  std::vector<double> residuals;
  ceres::CRSMatrix jacobian;
  if (!problem->Evaluate(evaluate, nullptr, &residuals, nullptr, &jacobian)) return std::nullopt;
  const int n = jacobian.num_cols;
  Eigen::MatrixXd hessian = Eigen::MatrixXd::Zero(n, n);
  Eigen::MatrixXd gradients = Eigen::MatrixXd::Zero(n, num_pairs);
  for (int r = 0; r < jacobian.num_rows; ++r) {
    for (int a = jacobian.rows[r]; a < jacobian.rows[r + 1]; ++a) {
      const int col = jacobian.cols[a];
      const double value = jacobian.values[a];
      gradients(col, row_pair[r]) += value * residuals[r];
      for (int b = jacobian.rows[r]; b < jacobian.rows[r + 1]; ++b) {
        hessian(col, jacobian.cols[b]) += value * jacobian.values[b];
      }
    }
  }
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(hessian);
  if (ldlt.info() != Eigen::Success || !(ldlt.vectorD().minCoeff() > 0.0)) return std::nullopt;
  const Eigen::MatrixXd influence = ldlt.solve(gradients).topRows<6>();  // 6 x pairs
  const Matrix6d covariance =
      influence * influence.transpose() * (num_pairs / (num_pairs - 1.0));
  if (!covariance.allFinite()) return std::nullopt;
  return covariance;
}

// `pair_residuals` (each pair's residual blocks), when not empty, adds the robust estimate.
RigUncertainty EstimateUncertainty(
    ceres::Problem* problem, RigBlocks* blocks,
    const std::vector<std::vector<ceres::ResidualBlockId>>& pair_residuals = {}) {
  RigUncertainty uncertainty;
  ceres::Covariance::Options covariance_options;
  // SPARSE_QR (SuiteSparse) rather than DENSE_SVD: the static libceres' Eigen SVD
  // instantiations clash with ours under AddressSanitizer (a bad free inside BDCSVD). A
  // rank-deficient Jacobian makes Compute() fail, and the uncertainty is then reported invalid.
  covariance_options.algorithm_type = ceres::SPARSE_QR;
  ceres::Covariance covariance(covariance_options);
  double* rig = blocks->cam0_from_cam1.data();
  const std::vector<std::pair<const double*, const double*>> blocks_wanted = {{rig, rig}};
  if (!covariance.Compute(blocks_wanted, problem)) return uncertainty;
  Eigen::Matrix<double, 6, 6, Eigen::RowMajor> tangent;
  if (!covariance.GetCovarianceBlockInTangentSpace(rig, rig, tangent.data())) return uncertainty;
  int num_residuals = 0;
  const double sum_squares = SumSquaredResiduals(problem, &num_residuals);
  const int dof = num_residuals - NumFreeParameters(*problem);
  if (dof <= 0) return uncertainty;
  const double sigma2 = sum_squares / dof;
  const RigStd std = StdOfTangentCovariance(tangent * sigma2, rig);
  uncertainty.translation_std_m = std.translation_m;
  uncertainty.baseline_std_m = std.baseline_m;
  uncertainty.rotation_std_deg = std.rotation_deg;
  uncertainty.valid = true;
  if (!pair_residuals.empty()) {
    if (const auto robust = ClusteredRigCovariance(problem, rig, pair_residuals)) {
      const RigStd robust_std = StdOfTangentCovariance(*robust, rig);
      uncertainty.robust_baseline_std_m = robust_std.baseline_m;
      uncertainty.robust_rotation_std_deg = robust_std.rotation_deg;
      uncertainty.robust_valid = true;
    }
  }
  return uncertainty;
}

}  // namespace

Eigen::Vector3d RigPairBoardCentre(const RigPairCorners& pair) {
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();
  for (const auto& p : pair.points_in_board0) centre += p;
  for (const auto& p : pair.points_in_board1) centre += p;
  const size_t n = pair.points_in_board0.size() + pair.points_in_board1.size();
  return n > 0 ? Eigen::Vector3d(centre / static_cast<double>(n)) : centre;
}

RigUncertainty EstimateRigUncertainty(const std::vector<RigPairCorners>& pairs,
                                      const RigRefinementOptions& options, const StereoRig& rig,
                                      const std::vector<Rigid3d>& cam0_from_board) {
  OMNIRIG_CHECK(cam0_from_board.size() == pairs.size(), "one board pose per pair expected");
  RigBlocks blocks = BlocksOf(rig, cam0_from_board);
  ceres::Problem problem;
  std::vector<std::vector<ceres::ResidualBlockId>> pair_residuals;
  AddResiduals(pairs, options, &blocks, &problem, &pair_residuals);
  return EstimateUncertainty(&problem, &blocks, pair_residuals);
}

SolverSummary RefineRig(const std::vector<RigPairCorners>& pairs,
                        const RigRefinementOptions& options, StereoRig* rig,
                        std::vector<Rigid3d>* cam0_from_board, RigUncertainty* uncertainty,
                        const ProgressSink& progress) {
  OMNIRIG_CHECK(cam0_from_board->size() == pairs.size(), "one board pose per pair expected");
  RigBlocks blocks = BlocksOf(*rig, *cam0_from_board);

  ceres::Problem problem;
  std::vector<std::vector<ceres::ResidualBlockId>> pair_residuals;
  AddResiduals(pairs, options, &blocks, &problem, &pair_residuals);

  // Board poses form the Schur complement's eliminated group; the rig pose and the two
  // intrinsics are few (3 blocks), so the reduced system is small and dense.
  ceres::Solver::Options solver_options = MakeSolverOptions(
      SolverSetup(3, options.max_num_iterations, std::max(1, options.num_threads))
          .Tolerances(1e-12, 1e-14, 1e-12));
  SolverProgress callback(progress, "refine", [&](int iteration) {
    return std::min(1.0, (iteration + 1.0) / options.max_num_iterations);
  });
  solver_options.callbacks.push_back(&callback);
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);
  progress.ThrowIfCancelled();

  const SolverSummary result = Summarize(summary);
  if (!result.usable) return result;

  rig->cam0_from_cam1 = Rigid3d::FromParams(blocks.cam0_from_cam1.data());
  for (size_t i = 0; i < pairs.size(); ++i) {
    (*cam0_from_board)[i] = Rigid3d::FromParams(blocks.cam0_from_board[i].data());
  }
  rig->cam0.intrinsics.params = blocks.intrinsics0;
  rig->cam1.intrinsics.params = blocks.intrinsics1;
  if (uncertainty != nullptr) {
    *uncertainty = EstimateUncertainty(&problem, &blocks, pair_residuals);
  }
  return result;
}

double FitBoardThroughRig(const StereoRig& rig, const RigPairCorners& pair,
                          const std::array<double, 2>& noise_px, Rigid3d* cam0_from_board) {
  OMNIRIG_CHECK(noise_px[0] > 0.0 && noise_px[1] > 0.0, "corner noise must be positive");
  std::array<double, 7> board = cam0_from_board->ToParams();
  // Weights 1 / sigma^2 on each camera's squared residuals: the problem's cost is then half
  // the whitened sum of squares.
  ceres::Problem::Options problem_options;
  problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  ceres::ScaledLoss weight0(nullptr, 1.0 / (noise_px[0] * noise_px[0]), ceres::TAKE_OWNERSHIP);
  ceres::ScaledLoss weight1(nullptr, 1.0 / (noise_px[1] * noise_px[1]), ceres::TAKE_OWNERSHIP);
  const Rigid3d cam1_from_cam0 = rig.cam0_from_cam1.Inverse();
  for (size_t c = 0; c < pair.pixels0.size(); ++c) {
    problem.AddResidualBlock(
        ReprojectionCost::BoardCornerFixedCamera(pair.points_in_board0[c], pair.pixels0[c],
                                                 Rigid3d(), rig.cam0.intrinsics),
        &weight0, board.data());
  }
  for (size_t c = 0; c < pair.pixels1.size(); ++c) {
    problem.AddResidualBlock(
        ReprojectionCost::BoardCornerFixedCamera(pair.points_in_board1[c], pair.pixels1[c],
                                                 cam1_from_cam0, rig.cam1.intrinsics),
        &weight1, board.data());
  }
  problem.SetManifold(board.data(), NewPoseManifold());
  const ceres::Solver::Options solver_options =
      MakeSolverOptions(SolverSetup(0, 50).Tolerances(1e-12, 1e-10, 1e-12));
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);
  if (!summary.IsSolutionUsable() || !std::isfinite(summary.final_cost)) return -1.0;
  *cam0_from_board = Rigid3d::FromParams(board.data());
  return 2.0 * summary.final_cost;
}

double PairRmsPx(const StereoRig& rig, const Rigid3d& cam0_from_board, const RigPairCorners& pair) {
  const Rigid3d cam1_from_board = rig.cam0_from_cam1.Inverse() * cam0_from_board;
  double sum = 0.0;
  int count = 0;
  const auto accumulate = [&](const CameraModel& camera, const Rigid3d& cam_from_board,
                              const std::vector<Eigen::Vector3d>& points,
                              const std::vector<Eigen::Vector2d>& pixels) {
    for (size_t c = 0; c < pixels.size(); ++c) {
      const auto projected = Project(camera.intrinsics, cam_from_board * points[c]);
      sum += projected ? (*projected - pixels[c]).squaredNorm() : 1e6;
      ++count;
    }
  };
  accumulate(rig.cam0, cam0_from_board, pair.points_in_board0, pair.pixels0);
  accumulate(rig.cam1, cam1_from_board, pair.points_in_board1, pair.pixels1);
  return count > 0 ? std::sqrt(sum / count) : 0.0;
}

}  // namespace omnirig
