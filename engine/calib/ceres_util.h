#pragma once
// Ceres pieces shared by the calibration problems: the pose manifold and the solver set-up.

#include <ceres/ceres.h>

namespace omnirig {

// A Rigid3d parameter block [qx, qy, qz, qw, tx, ty, tz]: Eigen-order quaternion x R^3.
inline ceres::Manifold* NewPoseManifold() {
  return new ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::EuclideanManifold<3>>(
      ceres::EigenQuaternionManifold(), ceres::EuclideanManifold<3>());
}

// The one place where calibration solvers are configured: LM, the Schur complement over the
// pose blocks (dense for the sizes calibration sees, sparse beyond), threads from the caller.
inline ceres::Solver::Options MakeCalibrationSolverOptions(int num_parameter_blocks,
                                                           int max_num_iterations,
                                                           int num_threads) {
  ceres::Solver::Options options;
  options.minimizer_type = ceres::TRUST_REGION;
  options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  options.linear_solver_type =
      num_parameter_blocks <= 200 ? ceres::DENSE_SCHUR : ceres::SPARSE_SCHUR;
  options.max_num_iterations = max_num_iterations;
  options.num_threads = num_threads;
  // Tolerances tight enough to reach the minimum on every set, without tuning per set.
  options.function_tolerance = 1e-10;
  options.gradient_tolerance = 1e-10;
  options.parameter_tolerance = 1e-10;
  options.logging_type = ceres::SILENT;
  return options;
}

}  // namespace omnirig
