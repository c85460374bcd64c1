#pragma once
// The geometry's Ceres layer, shared by calibration, relative pose and bundle adjustment: the
// pose manifold, the rotated point's Jacobian, the one solver set-up, its summary and its
// progress callback.
//
// Parameter blocks hold a Rigid3d as 7 doubles in Eigen's order [qx, qy, qz, qw, tx, ty, tz]
// (Rigid3d::ToParams).

#include <ceres/ceres.h>
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <functional>
#include <string>
#include <utility>

#include "engine/geometry/rigid3.h"
#include "engine/util/progress.h"
#include "engine/util/solver_summary.h"

namespace omnirig {

// A Rigid3d parameter block [qx, qy, qz, qw, tx, ty, tz]: Eigen-order quaternion x R^3.
inline ceres::Manifold* NewPoseManifold() {
  return new ceres::ProductManifold<ceres::EigenQuaternionManifold, ceres::EuclideanManifold<3>>(
      ceres::EigenQuaternionManifold(), ceres::EuclideanManifold<3>());
}

// d(q * v) / d[qx, qy, qz, qw] of Eigen's rotation v + 2 w (u x v) + 2 u x (u x v), u = (qx,
// qy, qz), w = qw: the formula itself, so also off the unit sphere, as Jets and numeric
// differences see it. (d(q * v) / dv is q.toRotationMatrix(), which is that formula's matrix
// for any q.)
inline Eigen::Matrix<double, 3, 4> RotatedPointJacobian(const Eigen::Quaterniond& q,
                                                        const Eigen::Vector3d& v) {
  const Eigen::Vector3d u = q.vec();
  Eigen::Matrix<double, 3, 4> jacobian;
  jacobian.leftCols<3>() = -2.0 * q.w() * Skew(v) + 2.0 * u.dot(v) * Eigen::Matrix3d::Identity() +
                           2.0 * u * v.transpose() - 4.0 * v * u.transpose();
  jacobian.col(3) = 2.0 * u.cross(v);
  return jacobian;
}

// What differs between the solves of the engine; everything else is set in MakeSolverOptions.
struct SolverSetup {
  // problem_size is what the linear solver is chosen by: 0 for a problem with nothing to
  // eliminate (one pose, a two-view geometry): DENSE_QR. Otherwise the Schur complement
  // eliminates the points or board poses, DENSE_SCHUR up to max_dense_schur_size and
  // SPARSE_SCHUR beyond; the size is what each caller measured the choice on (parameter blocks
  // of a calibration, free poses of a bundle adjustment).
  SolverSetup(int problem_size, int max_num_iterations, int num_threads = 1)
      : problem_size(problem_size),
        max_num_iterations(max_num_iterations),
        num_threads(num_threads) {}
  SolverSetup& DenseSchurUpTo(int size) {
    max_dense_schur_size = size;
    return *this;
  }
  SolverSetup& Tolerances(double function, double gradient, double parameter) {
    function_tolerance = function;
    gradient_tolerance = gradient;
    parameter_tolerance = parameter;
    return *this;
  }

  int problem_size;
  int max_num_iterations;
  int num_threads;  // the job's budget
  int max_dense_schur_size = 200;
  // Ceres' defaults unless a caller needs tighter.
  double function_tolerance = 1e-6;
  double gradient_tolerance = 1e-10;
  double parameter_tolerance = 1e-8;
};

// The one place where the engine's Ceres solvers are configured: Levenberg-Marquardt, the linear
// solver chosen by problem size, threads from the caller, silent.
inline ceres::Solver::Options MakeSolverOptions(const SolverSetup& setup) {
  ceres::Solver::Options options;
  options.minimizer_type = ceres::TRUST_REGION;
  options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  options.linear_solver_type = setup.problem_size == 0 ? ceres::DENSE_QR
                               : setup.problem_size <= setup.max_dense_schur_size
                                   ? ceres::DENSE_SCHUR
                                   : ceres::SPARSE_SCHUR;
  options.max_num_iterations = setup.max_num_iterations;
  options.num_threads = setup.num_threads;
  options.function_tolerance = setup.function_tolerance;
  options.gradient_tolerance = setup.gradient_tolerance;
  options.parameter_tolerance = setup.parameter_tolerance;
  options.logging_type = ceres::SILENT;
  options.minimizer_progress_to_stdout = false;
  return options;
}

// The engine's summary of one Ceres solve: every iteration counted (iteration 0 included),
// time from Ceres' own total.
inline SolverSummary Summarize(const ceres::Solver::Summary& summary) {
  SolverSummary out;
  out.num_iterations = static_cast<int>(summary.iterations.size());
  out.initial_cost = summary.initial_cost;
  out.final_cost = summary.final_cost;
  out.termination = ceres::TerminationTypeToString(summary.termination_type);
  out.time_s = summary.total_time_in_seconds;
  out.usable = summary.IsSolutionUsable();
  return out;
}

// Aborts a solve as soon as `progress` is cancelled (Ceres calls this after every iteration,
// well under a second apart even for the global adjustment; the caller then calls
// progress.ThrowIfCancelled()) and reports each iteration as `stage` at the fraction of the
// whole call that fraction_at(iteration) gives. `label` starts the message ("round 2, ").
class SolverProgress : public ceres::IterationCallback {
 public:
  SolverProgress(const ProgressSink& progress, std::string stage,
                 std::function<double(int iteration)> fraction_at, std::string label = "")
      : progress_(progress),
        stage_(std::move(stage)),
        fraction_at_(std::move(fraction_at)),
        label_(std::move(label)) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override {
    if (progress_.IsCancelled()) return ceres::SOLVER_ABORT;
    if (progress_.report) {
      progress_.Report(fraction_at_(summary.iteration), stage_,
                       label_ + "iteration " + std::to_string(summary.iteration) + ", cost " +
                           std::to_string(summary.cost));
    }
    return ceres::SOLVER_CONTINUE;
  }

 private:
  const ProgressSink& progress_;
  std::string stage_;
  std::function<double(int)> fraction_at_;
  std::string label_;
};

}  // namespace omnirig
