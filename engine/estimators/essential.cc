#include "engine/estimators/essential.h"

#include <algorithm>
#include <cmath>

#include <ceres/ceres.h>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include "engine/estimators/ransac.h"
#include "engine/estimators/triangulation.h"
#include "engine/geometry/ceres_problem.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"

namespace omnirig {
namespace {

// Hartley's conditioning transposed to bearings: a linear map T with (1/n) sum (T b)(T b)^T
// proportional to the identity, so that the nine columns of A in eq. (14) have comparable
// scale even when the bearings cover a narrow cone. Eigenvalues are clamped so that a
// degenerate (planar) set is not blown up.
Eigen::Matrix3d ConditioningTransform(const std::vector<Eigen::Vector3d>& bearings,
                                      const std::vector<int>& indices) {
  Eigen::Matrix3d moment = Eigen::Matrix3d::Zero();
  for (int i : indices) moment += bearings[i] * bearings[i].transpose();
  moment /= static_cast<double>(indices.size());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(moment);
  const Eigen::Vector3d values = eig.eigenvalues().cwiseMax(1e-6 * eig.eigenvalues().maxCoeff());
  return eig.eigenvectors() * values.cwiseSqrt().cwiseInverse().asDiagonal() *
         eig.eigenvectors().transpose();
}

// Eq. (15): the closest matrix with singular values (s, s, 0), returned with s = 1.
Eigen::Matrix3d EnforceEssentialConstraints(const Eigen::Matrix3d& e) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(e, Eigen::ComputeFullU | Eigen::ComputeFullV);
  return svd.matrixU() * Eigen::Vector3d(1.0, 1.0, 0.0).asDiagonal() * svd.matrixV().transpose();
}

// The minimal-sample and consensus-set estimator that the generic RANSAC drives.
class EssentialEstimator {
 public:
  using Model = Eigen::Matrix3d;
  static constexpr int kMinSampleSize = 8;

  EssentialEstimator(const std::vector<Eigen::Vector3d>& bearings1,
                     const std::vector<Eigen::Vector3d>& bearings2)
      : bearings1_(bearings1), bearings2_(bearings2) {}

  void Estimate(const std::vector<int>& sample, std::vector<Model>* models) const {
    const Model e = EssentialEightPoint(bearings1_, bearings2_, sample);
    if (e.allFinite()) models->push_back(e);
  }
  bool Refit(const std::vector<int>& indices, Model* model) const {
    const Model e = EssentialEightPoint(bearings1_, bearings2_, indices);
    if (!e.allFinite()) return false;
    *model = e;
    return true;
  }
  // The sine of eq. (16)'s angle: monotone in it, and cheaper (RANSAC compares it with the
  // sine of the threshold).
  double Error(const Model& e, int i) const {
    const Eigen::Vector3d normal = e * bearings1_[i];
    const double norm = normal.norm();
    return norm > 0.0 ? std::abs(bearings2_[i].dot(normal)) / norm : 0.0;
  }
  int NumData() const { return static_cast<int>(bearings1_.size()); }

 private:
  const std::vector<Eigen::Vector3d>& bearings1_;
  const std::vector<Eigen::Vector3d>& bearings2_;
};

// Residual of eq. (16) for the Ceres refinement: the sine of the angle between b2 and the
// epipolar plane spanned by t and R b1 (in camera 2).
struct EpipolarAngularResidual {
  EpipolarAngularResidual(const Eigen::Vector3d& b1, const Eigen::Vector3d& b2)
      : b1_(b1), b2_(b2) {}

  template <typename T>
  bool operator()(const T* rotation_xyzw, const T* translation, T* residual) const {
    const Eigen::Map<const Eigen::Quaternion<T>> q(rotation_xyzw);
    const Eigen::Map<const Eigen::Matrix<T, 3, 1>> t(translation);
    const Eigen::Matrix<T, 3, 1> normal = t.cross(q * b1_.cast<T>());
    const T norm2 = normal.squaredNorm();
    if (!(norm2 > T(1e-24))) {
      residual[0] = T(0);
      return true;
    }
    residual[0] = b2_.cast<T>().dot(normal) / sqrt(norm2);
    return true;
  }

  static ceres::CostFunction* Create(const Eigen::Vector3d& b1, const Eigen::Vector3d& b2) {
    return new ceres::AutoDiffCostFunction<EpipolarAngularResidual, 1, 4, 3>(
        new EpipolarAngularResidual(b1, b2));
  }

 private:
  Eigen::Vector3d b1_;
  Eigen::Vector3d b2_;
};

std::vector<int> AllIndices(size_t n) {
  std::vector<int> indices(n);
  for (size_t i = 0; i < n; ++i) indices[i] = static_cast<int>(i);
  return indices;
}

EssentialReport Fail(EssentialReport report, const std::string& reason) {
  report.success = false;
  report.reason = reason;
  return report;
}

// Inlier mask, count, RMS angular error and median parallax of report->E / cam2_from_cam1.
void ScoreModel(const std::vector<Eigen::Vector3d>& bearings1,
                const std::vector<Eigen::Vector3d>& bearings2, double max_angular_error_rad,
                EssentialReport* report) {
  double sum_sq = 0.0;
  report->num_inliers = 0;
  for (size_t i = 0; i < bearings1.size(); ++i) {
    const double error = EpipolarAngularError(report->E, bearings1[i], bearings2[i]);
    report->inlier_mask[i] = error <= max_angular_error_rad;
    if (report->inlier_mask[i]) {
      ++report->num_inliers;
      sum_sq += error * error;
    }
  }
  report->rms_angular_error_rad =
      report->num_inliers > 0 ? std::sqrt(sum_sq / report->num_inliers) : 0.0;

  TriangulationOptions triangulation;
  triangulation.min_parallax_rad = 0.0;
  triangulation.max_angular_error_rad = 0.25 * M_PI;  // only "in front of both" matters here
  std::vector<double> parallax;
  for (size_t i = 0; i < bearings1.size(); ++i) {
    if (!report->inlier_mask[i]) continue;
    const TriangulatedPoint t =
        TriangulateMidpoint(report->cam2_from_cam1, bearings1[i], bearings2[i], triangulation);
    if (t.valid) parallax.push_back(t.parallax_rad);
  }
  if (!parallax.empty()) {
    std::nth_element(parallax.begin(), parallax.begin() + parallax.size() / 2, parallax.end());
    report->median_parallax_rad = parallax[parallax.size() / 2];
  }
}

}  // namespace

double EpipolarAngularError(const Eigen::Matrix3d& E, const Eigen::Vector3d& b1,
                            const Eigen::Vector3d& b2) {
  const Eigen::Vector3d normal = E * b1;
  const double denom = normal.norm() * b2.norm();
  if (!(denom > 0.0)) return 0.0;
  return std::asin(std::min(1.0, std::abs(b2.dot(normal)) / denom));
}

Eigen::Matrix3d EssentialFromPose(const Rigid3d& cam2_from_cam1) {
  return Skew(cam2_from_cam1.translation) * cam2_from_cam1.RotationMatrix();
}

Eigen::Matrix3d EssentialEightPoint(const std::vector<Eigen::Vector3d>& bearings1,
                                    const std::vector<Eigen::Vector3d>& bearings2,
                                    const std::vector<int>& indices_in) {
  OMNIRIG_CHECK(bearings1.size() == bearings2.size(),
                "EssentialEightPoint: " << bearings1.size() << " bearings in camera 1 but "
                                        << bearings2.size() << " in camera 2");
  const std::vector<int> indices = indices_in.empty() ? AllIndices(bearings1.size()) : indices_in;
  OMNIRIG_CHECK(indices.size() >= 8,
                "EssentialEightPoint: needs at least 8 pairs, got " << indices.size());
  for (int i : indices) {
    OMNIRIG_CHECK(i >= 0 && i < static_cast<int>(bearings1.size()),
                  "EssentialEightPoint: index " << i << " out of range");
  }
  const Eigen::Matrix3d t1 = ConditioningTransform(bearings1, indices);
  const Eigen::Matrix3d t2 = ConditioningTransform(bearings2, indices);

  // Eq. (13) row for one pair: kron(b2, b1) against e in row-major order; eq. (14) solved as
  // the eigenvector of A^T A with the smallest eigenvalue (A is n x 9, A^T A is 9 x 9).
  Eigen::Matrix<double, 9, 9> ata = Eigen::Matrix<double, 9, 9>::Zero();
  for (int i : indices) {
    const Eigen::Vector3d x1 = t1 * bearings1[i];
    const Eigen::Vector3d x2 = t2 * bearings2[i];
    Eigen::Matrix<double, 9, 1> row;
    row << x2.x() * x1, x2.y() * x1, x2.z() * x1;
    ata.selfadjointView<Eigen::Lower>().rankUpdate(row);
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> eig(
      ata.selfadjointView<Eigen::Lower>());
  const Eigen::Matrix<double, 9, 1> e = eig.eigenvectors().col(0);
  Eigen::Matrix3d conditioned;
  conditioned << e(0), e(1), e(2), e(3), e(4), e(5), e(6), e(7), e(8);
  // Undo the conditioning before enforcing the constraints: x2^T E' x1 = b2^T (T2^T E' T1) b1.
  return EnforceEssentialConstraints(t2.transpose() * conditioned * t1);
}

std::vector<Rigid3d> DecomposeEssential(const Eigen::Matrix3d& E) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(E, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d u = svd.matrixU();
  Eigen::Matrix3d v = svd.matrixV();
  // E is defined up to sign, so flipping a column keeps a valid factorisation with proper
  // rotations in U and V.
  if (u.determinant() < 0) u.col(2) *= -1.0;
  if (v.determinant() < 0) v.col(2) *= -1.0;
  // Eq. (17): R = (-u2, u1, +-u3) V^T and (u2, -u1, +-u3) V^T; with det(U) = det(V) = 1 the two
  // proper rotations are U W V^T and U W^T V^T. With E = [t]_x R (t in camera 2) the
  // translation is +-u3; the paper's +-v3 is the same direction expressed in camera 1.
  Eigen::Matrix3d w;
  w << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  const Eigen::Matrix3d r_a = u * w * v.transpose();
  const Eigen::Matrix3d r_b = u * w.transpose() * v.transpose();
  const Eigen::Vector3d t = u.col(2).normalized();
  return {Rigid3d(Eigen::Quaterniond(r_a), t), Rigid3d(Eigen::Quaterniond(r_a), -t),
          Rigid3d(Eigen::Quaterniond(r_b), t), Rigid3d(Eigen::Quaterniond(r_b), -t)};
}

int SelectDecomposition(const std::vector<Rigid3d>& candidates,
                        const std::vector<Eigen::Vector3d>& bearings1,
                        const std::vector<Eigen::Vector3d>& bearings2,
                        const std::vector<int>& indices, double max_angular_error_rad,
                        int* num_supporting) {
  TriangulationOptions triangulation;
  triangulation.min_parallax_rad = 0.0;
  triangulation.max_angular_error_rad = max_angular_error_rad;
  int best = -1;
  int best_count = 0;
  for (size_t c = 0; c < candidates.size(); ++c) {
    int count = 0;
    for (int i : indices) {
      if (TriangulateMidpoint(candidates[c], bearings1[i], bearings2[i], triangulation).valid) {
        ++count;
      }
    }
    if (count > best_count) {
      best_count = count;
      best = static_cast<int>(c);
    }
  }
  if (num_supporting) *num_supporting = best_count;
  return best;
}

void EssentialRansacOptions::Check() const {
  OMNIRIG_CHECK_IN(max_angular_error_rad, '(', 0, 0.5 * M_PI, ')');
  OMNIRIG_CHECK_AT_LEAST(max_iterations, 1);
  OMNIRIG_CHECK_IN(confidence, '(', 0, 1, ')');
  OMNIRIG_CHECK_AT_LEAST(min_inliers, 8);
}

bool RefineRelativePose(const std::vector<Eigen::Vector3d>& bearings1,
                        const std::vector<Eigen::Vector3d>& bearings2,
                        const std::vector<int>& indices, double loss_scale_rad,
                        Rigid3d* cam2_from_cam1) {
  std::array<double, 7> params = cam2_from_cam1->ToParams();
  Eigen::Map<Eigen::Vector3d> translation(params.data() + 4);
  if (!(translation.norm() > 0.0)) return false;
  translation.normalize();
  ceres::Problem problem;
  for (int i : indices) {
    problem.AddResidualBlock(EpipolarAngularResidual::Create(bearings1[i], bearings2[i]),
                             new ceres::CauchyLoss(loss_scale_rad), params.data(),
                             params.data() + 4);
  }
  if (problem.NumResidualBlocks() == 0) return false;
  problem.SetManifold(params.data(), new ceres::EigenQuaternionManifold());
  // Scale is not observable: the translation lives on the unit sphere (the gauge).
  problem.SetManifold(params.data() + 4, new ceres::SphereManifold<3>());
  const ceres::Solver::Options options = MakeSolverOptions(SolverSetup(0, 20));
  ceres::Solver::Summary summary;
  ceres::Solve(options, &problem, &summary);
  if (!summary.IsSolutionUsable() || !std::isfinite(summary.final_cost)) return false;
  *cam2_from_cam1 = Rigid3d::FromParams(params.data());
  return true;
}

EssentialReport EstimateEssentialRansac(const std::vector<Eigen::Vector3d>& bearings1,
                                        const std::vector<Eigen::Vector3d>& bearings2,
                                        const EssentialRansacOptions& options) {
  options.Check();
  OMNIRIG_CHECK(bearings1.size() == bearings2.size(),
                "EstimateEssentialRansac: " << bearings1.size() << " bearings in camera 1 but "
                                            << bearings2.size() << " in camera 2");
  EssentialReport report;
  const int n = static_cast<int>(bearings1.size());
  report.inlier_mask.assign(n, 0);
  if (n < options.min_inliers) {
    return Fail(report, "too few pairs: " + std::to_string(n) + " < min_inliers " +
                            std::to_string(options.min_inliers));
  }
  for (int i = 0; i < n; ++i) {
    OMNIRIG_CHECK(bearings1[i].allFinite() && bearings2[i].allFinite() &&
                      bearings1[i].norm() > 0.0 && bearings2[i].norm() > 0.0,
                  "EstimateEssentialRansac: pair " << i << " holds a zero or non-finite bearing");
  }

  RansacOptions ransac;
  ransac.max_error = std::sin(options.max_angular_error_rad);
  ransac.max_iterations = options.max_iterations;
  ransac.confidence = options.confidence;
  ransac.seed = options.seed;
  const EssentialEstimator estimator(bearings1, bearings2);
  const RansacReport<Eigen::Matrix3d> found = Ransac(estimator, ransac);
  report.num_iterations = found.num_iterations;
  if (!found.success || found.num_inliers < options.min_inliers) {
    return Fail(report, "no essential matrix with at least " + std::to_string(options.min_inliers) +
                            " inliers");
  }

  std::vector<int> inliers;
  for (int i = 0; i < n; ++i) {
    if (found.inlier_mask[i]) inliers.push_back(i);
  }
  const std::vector<Rigid3d> candidates = DecomposeEssential(found.model);
  // Triangulation-based choice tolerates a few times the epipolar threshold: the midpoint's
  // reprojection error exceeds the epipolar error, and a wrong candidate is off by ~pi anyway.
  const double support_threshold = std::max(10.0 * options.max_angular_error_rad, 0.01);
  const int chosen =
      SelectDecomposition(candidates, bearings1, bearings2, inliers, support_threshold, nullptr);
  if (chosen < 0) return Fail(report, "no decomposition of E triangulates any inlier");
  Rigid3d pose = candidates[chosen];
  if (options.refine) {
    RefineRelativePose(bearings1, bearings2, inliers, options.max_angular_error_rad, &pose);
  }

  report.cam2_from_cam1 = pose;
  report.E = EssentialFromPose(pose);
  ScoreModel(bearings1, bearings2, options.max_angular_error_rad, &report);
  if (report.num_inliers < options.min_inliers) {
    return Fail(report, "refined model keeps fewer than min_inliers inliers");
  }
  report.success = true;
  return report;
}

}  // namespace omnirig
