#include "engine/estimators/absolute_pose.h"

#include <cmath>
#include <functional>
#include <memory>
#include <random>

#include <opengv/absolute_pose/CentralAbsoluteAdapter.hpp>
#include <opengv/absolute_pose/methods.hpp>
#include <opengv/sac/Ransac.hpp>
#include <opengv/sac_problems/absolute_pose/AbsolutePoseSacProblem.hpp>

#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {
namespace {

using opengv::sac_problems::absolute_pose::AbsolutePoseSacProblem;

// OpenGV's absolute-pose problem with its sample generator seeded from `seed`.
class SeededAbsolutePoseProblem : public AbsolutePoseSacProblem {
 public:
  SeededAbsolutePoseProblem(opengv::absolute_pose::AbsoluteAdapterBase& adapter,
                            std::uint64_t seed)
      : AbsolutePoseSacProblem(adapter, AbsolutePoseSacProblem::KNEIP, /*randomSeed=*/false) {
    rng_alg_.seed(static_cast<std::mt19937::result_type>(seed ^ 0x9e3779b97f4a7c15ULL));
    rng_gen_.reset(new std::function<int()>(std::bind(*rng_dist_, rng_alg_)));
  }
};

}  // namespace

void AbsolutePoseOptions::Check() const {
  OMNIRIG_CHECK_IN(max_angular_error_rad, '(', 0, 0.5, ')');
  OMNIRIG_CHECK_AT_LEAST(max_iterations, 1);
  OMNIRIG_CHECK_AT_LEAST(min_inliers, 4);
}

AbsolutePoseReport EstimateAbsolutePose(const std::vector<Eigen::Vector3d>& bearings_in_rig,
                                        const std::vector<Eigen::Vector3d>& points_in_world,
                                        const AbsolutePoseOptions& options) {
  options.Check();
  OMNIRIG_CHECK(bearings_in_rig.size() == points_in_world.size(),
                "absolute pose needs one world point per bearing");
  AbsolutePoseReport report;
  const int n = static_cast<int>(bearings_in_rig.size());
  if (n < options.min_inliers) {
    report.reason = "too few correspondences (" + std::to_string(n) + ")";
    return report;
  }
  opengv::bearingVectors_t bearings(bearings_in_rig.begin(), bearings_in_rig.end());
  opengv::points_t points(points_in_world.begin(), points_in_world.end());
  opengv::absolute_pose::CentralAbsoluteAdapter adapter(bearings, points);
  opengv::sac::Ransac<AbsolutePoseSacProblem> ransac;
  ransac.sac_model_ = std::make_shared<SeededAbsolutePoseProblem>(adapter, options.seed);
  ransac.threshold_ = 1.0 - std::cos(options.max_angular_error_rad);
  ransac.max_iterations_ = options.max_iterations;
  if (!ransac.computeModel() || static_cast<int>(ransac.inliers_.size()) < options.min_inliers) {
    report.reason = "no pose with " + std::to_string(options.min_inliers) + " inliers (best " +
                    std::to_string(ransac.inliers_.size()) + " of " + std::to_string(n) + ")";
    return report;
  }
  // world_from_rig as [R t]; refined on the inliers.
  adapter.sett(ransac.model_coefficients_.col(3));
  adapter.setR(ransac.model_coefficients_.leftCols<3>());
  const opengv::transformation_t refined =
      opengv::absolute_pose::optimize_nonlinear(adapter, ransac.inliers_);
  const Eigen::Matrix3d rotation = refined.leftCols<3>();
  const Rigid3d world_from_rig(Eigen::Quaterniond(rotation), refined.col(3));
  report.rig_from_world = world_from_rig.Inverse();
  report.inlier_mask.assign(n, 0);
  const double min_cos = std::cos(options.max_angular_error_rad);
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d in_rig = report.rig_from_world * points_in_world[i];
    if (in_rig.normalized().dot(bearings_in_rig[i]) >= min_cos) {
      report.inlier_mask[i] = 1;
      ++report.num_inliers;
    }
  }
  report.success = report.num_inliers >= options.min_inliers;
  if (!report.success) report.reason = "too few inliers after refinement";
  return report;
}

}  // namespace omnirig
