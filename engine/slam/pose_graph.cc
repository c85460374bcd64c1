#include "engine/slam/pose_graph.h"

#include <array>

#include <ceres/ceres.h>
#include <Eigen/Geometry>

#include "engine/geometry/ceres_problem.h"
#include "engine/util/check.h"

namespace omnirig::slam {
namespace {

// The error of one edge: the estimated to_from_from against the measured one, as the
// translation difference (metres, in the `to` frame) and twice the vector part of the rotation
// difference (radians for small angles), each over its sigma.
struct RelativePoseCost {
  RelativePoseCost(const Rigid3d& measured, double sigma_m, double sigma_rad)
      : measured_rotation_inverse(measured.rotation.conjugate()),
        measured_translation(measured.translation),
        sigma_m(sigma_m),
        sigma_rad(sigma_rad) {}

  template <typename T>
  bool operator()(const T* from_pose, const T* to_pose, T* residuals) const {
    // Parameter blocks in Eigen order [qx, qy, qz, qw, tx, ty, tz] (Rigid3d::ToParams).
    const Eigen::Map<const Eigen::Quaternion<T>> q_from(from_pose);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> t_from(from_pose + 4);
    const Eigen::Map<const Eigen::Quaternion<T>> q_to(to_pose);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> t_to(to_pose + 4);
    const Eigen::Quaternion<T> q_estimate = q_to * q_from.conjugate();
    const Eigen::Matrix<T, 3, 1> t_estimate = t_to - q_estimate * t_from;
    const Eigen::Quaternion<T> q_error =
        measured_rotation_inverse.template cast<T>() * q_estimate;
    const Eigen::Matrix<T, 3, 1> t_error = t_estimate - measured_translation.template cast<T>();
    for (int i = 0; i < 3; ++i) {
      residuals[i] = t_error[i] / T(sigma_m);
      residuals[3 + i] = T(2.0) * q_error.vec()[i] / T(sigma_rad);
    }
    return true;
  }

  static ceres::CostFunction* Create(const PoseGraphEdge& edge) {
    return new ceres::AutoDiffCostFunction<RelativePoseCost, 6, 7, 7>(
        new RelativePoseCost(edge.to_from_from, edge.sigma_m, edge.sigma_rad));
  }

  Eigen::Quaterniond measured_rotation_inverse;
  Eigen::Vector3d measured_translation;
  double sigma_m;
  double sigma_rad;
};

}  // namespace

PoseGraphReport OptimisePoseGraph(const std::vector<PoseGraphEdge>& edges,
                                  const std::set<int>& fixed, int num_threads,
                                  std::map<int, Rigid3d>* rig_from_world) {
  OMNIRIG_CHECK(!fixed.empty(), "a pose graph needs at least one fixed pose");
  std::map<int, std::array<double, 7>> params;
  for (const auto& [keyframe, pose] : *rig_from_world) params[keyframe] = pose.ToParams();
  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  for (auto& [keyframe, p] : params) problem.AddParameterBlock(p.data(), 7, NewPoseManifold());
  for (const PoseGraphEdge& edge : edges) {
    OMNIRIG_CHECK(params.count(edge.from) && params.count(edge.to),
                  "pose graph edge between unknown keyframes " << edge.from << ", " << edge.to);
    // Once the correction is spread, the edges agree to their noise: no robust loss (the loop
    // edges were verified geometrically before they entered).
    problem.AddResidualBlock(RelativePoseCost::Create(edge), nullptr, params[edge.from].data(),
                             params[edge.to].data());
  }
  for (int keyframe : fixed) {
    OMNIRIG_CHECK(params.count(keyframe), "fixed pose " << keyframe << " is not in the graph");
    problem.SetParameterBlockConstant(params[keyframe].data());
  }
  ceres::Solver::Options solver = MakeSolverOptions(SolverSetup(0, 100, num_threads));
  // A chain of poses with a few loops: a sparse normal matrix, nothing to eliminate.
  solver.linear_solver_type = ceres::SPARSE_NORMAL_CHOLESKY;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  for (auto& [keyframe, pose] : *rig_from_world) {
    pose = Rigid3d::FromParams(params[keyframe].data());
  }
  PoseGraphReport report;
  report.num_poses = static_cast<int>(params.size());
  report.solver = Summarize(summary);
  return report;
}

}  // namespace omnirig::slam
