#include "engine/slam/bundle_adjustment.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>
#include <set>
#include <sstream>

#include <ceres/jet.h>

#include "engine/calib/ceres_util.h"
#include "engine/util/check.h"
#include "engine/util/timer.h"

namespace omnirig::slam {
namespace {

Eigen::Matrix3d Skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

// Whether a landmark enters the adjustment: seen by a free frame, and from at least two rig
// positions. A landmark seen from one position only (by both cameras) carries no information
// on the poses with the calibration fixed: its point absorbs any change of that pose.
// Free frames as flags indexed by frame: the adjustment asks per observation.
using FrameFlags = std::vector<char>;

bool Adjustable(const Landmark& landmark, const FrameFlags& free_frames, const SlamMap& map) {
  if (!landmark.valid) return false;
  bool seen_by_free = false;
  int first_frame = -1;
  bool two_frames = false;
  for (const Observation& o : landmark.observations) {
    if (!map.has_pose[o.frame]) continue;
    seen_by_free = seen_by_free || free_frames[o.frame];
    if (first_frame < 0) first_frame = o.frame;
    two_frames = two_frames || o.frame != first_frame;
  }
  return seen_by_free && two_frames;
}

// Squared pixel error of one observation, or nullopt when the point does not project.
std::optional<double> SquaredError(const StereoRig& rig, const Rigid3d& rig_from_world,
                                   const Eigen::Vector3d& point_in_world,
                                   const Observation& observation) {
  const CameraModel& camera = observation.camera == 0 ? rig.cam0 : rig.cam1;
  const Eigen::Vector3d point_in_cam =
      CamFromRig(rig, observation.camera) * (rig_from_world * point_in_world);
  const std::optional<Eigen::Vector2d> pixel = Project(camera.intrinsics, point_in_cam);
  if (!pixel) return std::nullopt;
  return (*pixel - observation.pixel).squaredNorm();
}

ceres::Solver::Options SolverOptions(const BundleAdjustmentOptions& options, int num_free_poses,
                                     int max_iterations) {
  ceres::Solver::Options solver;
  solver.linear_solver_type = num_free_poses <= options.max_dense_schur_poses
                                  ? ceres::DENSE_SCHUR
                                  : ceres::SPARSE_SCHUR;
  solver.max_num_iterations = max_iterations;
  solver.num_threads = options.num_threads;
  solver.function_tolerance = 1e-6;
  solver.gradient_tolerance = 1e-10;
  solver.parameter_tolerance = 1e-8;
  solver.logging_type = ceres::SILENT;
  solver.minimizer_progress_to_stdout = false;
  return solver;
}

// Aborts the solver as soon as the sink is cancelled (Ceres calls this after every iteration,
// well under a second apart even for the global adjustment) and reports the iterations.
class ProgressCallback : public ceres::IterationCallback {
 public:
  // Iterations are counted from `offset` out of `budget` (the solves of one adjustment).
  ProgressCallback(const ProgressSink& progress, int offset, int budget)
      : progress_(progress), offset_(offset), budget_(budget) {}
  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override {
    if (progress_.IsCancelled()) return ceres::SOLVER_ABORT;
    if (progress_.report) {
      progress_.Report(std::min(1.0, (offset_ + summary.iteration) / static_cast<double>(budget_)),
                       "bundle_adjustment",
                       "iteration " + std::to_string(summary.iteration) + ", cost " +
                           std::to_string(summary.cost));
    }
    return ceres::SOLVER_CONTINUE;
  }

 private:
  const ProgressSink& progress_;
  int offset_;
  int budget_;
};

// Iterations of the first and the (optional) second solve of BundleAdjust().
int SecondSolveIterations(const BundleAdjustmentOptions& options) {
  return std::max(5, options.max_iterations / 2);
}

// Counts the constant poses; without any, holds the first pose constant (the gauge: stereo
// fixes the scale, one pose the other six degrees of freedom).
void FixGauge(const FrameFlags& free_frames, std::map<int, std::array<double, 7>>* poses,
              ceres::Problem* problem, BundleAdjustmentReport* report) {
  report->num_constant_poses = 0;
  for (auto& [frame, params] : *poses) {
    if (!free_frames[frame]) ++report->num_constant_poses;
  }
  if (report->num_constant_poses == 0 && !poses->empty()) {
    problem->SetParameterBlockConstant(poses->begin()->second.data());
    report->num_constant_poses = 1;
  }
  report->num_free_poses = static_cast<int>(poses->size()) - report->num_constant_poses;
}

// The calibration as parameter blocks of an adjustment that refines it.
struct CalibrationBlocks {
  explicit CalibrationBlocks(const StereoRig& rig)
      : intrinsics{rig.cam0.intrinsics.params, rig.cam1.intrinsics.params},
        rotation(rig.cam0_from_cam1.rotation.coeffs()),
        translation(rig.cam0_from_cam1.translation) {}
  // Adds the blocks with their manifolds (the fixed subset of the intrinsics, the rig's
  // rotation) or holds them constant; the rig's translation is always constant.
  void AddTo(const CalibrationRefinementOptions& refinement, ceres::Problem* problem,
             ceres::ParameterBlockOrdering* ordering) {
    using I = UnifiedIntrinsics;
    std::vector<int> fixed;
    for (int i = 0; i < I::kNumParams; ++i) {
      if (refinement.fixed_intrinsics[i]) continue;
      const bool linear = i == I::kGammaU || i == I::kGammaV || i == I::kU0 || i == I::kV0 ||
                          i == I::kAlpha;
      nonlinear_intrinsics_free = nonlinear_intrinsics_free || !linear;
    }
    nonlinear_intrinsics_free = nonlinear_intrinsics_free && refinement.RefinesIntrinsics();
    for (int i = 0; i < I::kNumParams; ++i) {
      if (refinement.fixed_intrinsics[i]) fixed.push_back(i);
    }
    for (auto& block : intrinsics) {
      problem->AddParameterBlock(block.data(), UnifiedIntrinsics::kNumParams);
      ordering->AddElementToGroup(block.data(), 1);
      if (!refinement.RefinesIntrinsics()) {
        problem->SetParameterBlockConstant(block.data());
      } else if (!fixed.empty()) {
        problem->SetManifold(block.data(),
                             new ceres::SubsetManifold(UnifiedIntrinsics::kNumParams, fixed));
      }
    }
    problem->AddParameterBlock(rotation.data(), 4, new ceres::EigenQuaternionManifold());
    ordering->AddElementToGroup(rotation.data(), 1);
    if (!refinement.RefinesRig()) problem->SetParameterBlockConstant(rotation.data());
    problem->AddParameterBlock(translation.data(), 3);
    ordering->AddElementToGroup(translation.data(), 1);
    problem->SetParameterBlockConstant(translation.data());
  }
  void WriteTo(StereoRig* rig) const {
    rig->cam0.intrinsics.params = intrinsics[0];
    rig->cam1.intrinsics.params = intrinsics[1];
    const std::array<double, 7> params = {rotation[0],    rotation[1],    rotation[2],
                                          rotation[3],    translation[0], translation[1],
                                          translation[2]};
    rig->cam0_from_cam1 = Rigid3d::FromParams(params.data());
  }
  std::array<double, UnifiedIntrinsics::kNumParams> intrinsics[2];
  Eigen::Vector4d rotation;     // Eigen order [x, y, z, w]
  Eigen::Vector3d translation;
  bool nonlinear_intrinsics_free = false;  // xi or k1..k5 refined
};

// One observation's residual: the fixed-calibration cost, or the one over the calibration
// blocks too.
void AddObservation(const StereoRig& rig, const Rigid3d (&cam_from_rig)[2],
                    CalibrationBlocks* calibration, const Observation& o, double* pose,
                    double* point, ceres::LossFunction* loss, ceres::Problem* problem) {
  if (calibration == nullptr) {
    const CameraModel& camera = o.camera == 0 ? rig.cam0 : rig.cam1;
    problem->AddResidualBlock(
        new RigReprojectionCost(camera.intrinsics, cam_from_rig[o.camera], o.pixel), loss, pose,
        point);
  } else if (o.camera == 0) {
    problem->AddResidualBlock(
        new RigCalibrationCost(0, o.pixel, calibration->nonlinear_intrinsics_free), loss,
        {pose, point, calibration->intrinsics[0].data()});
  } else {
    problem->AddResidualBlock(
        new RigCalibrationCost(1, o.pixel, calibration->nonlinear_intrinsics_free), loss,
        {pose, point, calibration->intrinsics[1].data(), calibration->rotation.data(),
         calibration->translation.data()});
  }
}

// One build-and-solve of the problem described at BundleAdjust(); writes the solution back,
// the calibration too when `refinement` is given.
ceres::Solver::Summary SolveOnce(const CalibrationRefinementOptions* refinement,
                                 const FrameFlags& free_frames, const std::vector<int>& candidates,
                                 const BundleAdjustmentOptions& options, int max_iterations,
                                 const ProgressSink& progress, int iteration_offset,
                                 StereoRig* rig, SlamMap* map, BundleAdjustmentReport* report) {
  std::map<int, std::array<double, 7>> poses;
  std::vector<int> landmark_ids;
  for (int id : candidates) {
    if (Adjustable(map->landmarks[id], free_frames, *map)) landmark_ids.push_back(id);
  }
  std::vector<std::array<double, 3>> points(landmark_ids.size());
  const Rigid3d cam_from_rig[2] = {CamFromRig(*rig, 0), CamFromRig(*rig, 1)};

  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  ceres::LossFunction* loss = new ceres::HuberLoss(options.huber_scale_px);
  auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
  std::optional<CalibrationBlocks> calibration;
  if (refinement) {
    calibration.emplace(*rig);
    calibration->AddTo(*refinement, &problem, ordering.get());
  }
  int num_residuals = 0;
  for (size_t i = 0; i < landmark_ids.size(); ++i) {
    const Landmark& landmark = map->landmarks[landmark_ids[i]];
    points[i] = {landmark.point_in_world.x(), landmark.point_in_world.y(),
                 landmark.point_in_world.z()};
    for (const Observation& o : landmark.observations) {
      if (!map->has_pose[o.frame]) continue;
      auto [it, inserted] = poses.try_emplace(o.frame, map->rig_from_world[o.frame].ToParams());
      if (inserted) {
        problem.AddParameterBlock(it->second.data(), 7, NewPoseManifold());
        ordering->AddElementToGroup(it->second.data(), 1);
        if (!free_frames[o.frame]) problem.SetParameterBlockConstant(it->second.data());
      }
      AddObservation(*rig, cam_from_rig, calibration ? &*calibration : nullptr, o,
                     it->second.data(), points[i].data(), loss, &problem);
      ++num_residuals;
    }
    if (problem.HasParameterBlock(points[i].data())) {
      ordering->AddElementToGroup(points[i].data(), 0);
    }
  }
  FixGauge(free_frames, &poses, &problem, report);
  report->num_points = static_cast<int>(landmark_ids.size());
  report->num_residuals = 2 * num_residuals;

  ceres::Solver::Summary summary;
  if (num_residuals == 0) {
    delete loss;  // the problem owns only loss functions it was given
    return summary;
  }
  ceres::Solver::Options solver = SolverOptions(options, report->num_free_poses, max_iterations);
  solver.linear_solver_ordering = ordering;
  ProgressCallback callback(progress, iteration_offset,
                            options.max_iterations + SecondSolveIterations(options));
  solver.callbacks.push_back(&callback);
  ceres::Solve(solver, &problem, &summary);
  progress.ThrowIfCancelled();

  for (const auto& [frame, params] : poses) {
    map->rig_from_world[frame] = Rigid3d::FromParams(params.data());
  }
  for (size_t i = 0; i < landmark_ids.size(); ++i) {
    map->landmarks[landmark_ids[i]].point_in_world =
        Eigen::Vector3d(points[i][0], points[i][1], points[i][2]);
  }
  if (calibration) calibration->WriteTo(rig);
  return summary;
}

// RMS error over the observations of landmarks seen by a free frame; with `prune`, removes
// observations above the threshold (and landmarks left with fewer than two).
double RmsAndPrune(const StereoRig& rig, const FrameFlags& free_frames,
                   const std::vector<int>& candidates, double max_error_px,
                   bool prune, SlamMap* map, BundleAdjustmentReport* report) {
  double sum_sq = 0;
  int count = 0;
  const double max_sq = max_error_px * max_error_px;
  for (int id : candidates) {
    Landmark& landmark = map->landmarks[id];
    if (!Adjustable(landmark, free_frames, *map)) continue;
    std::vector<Observation> kept;
    for (const Observation& o : landmark.observations) {
      if (!map->has_pose[o.frame]) continue;
      const std::optional<double> e2 =
          SquaredError(rig, map->rig_from_world[o.frame], landmark.point_in_world, o);
      if (prune && (!e2 || *e2 > max_sq)) {
        ++report->num_observations_pruned;
        continue;
      }
      kept.push_back(o);
      if (e2) {
        sum_sq += *e2;
        ++count;
      }
    }
    if (!prune) continue;
    landmark.observations = std::move(kept);
    if (landmark.observations.size() < 2) {
      landmark.valid = false;
      ++report->num_points_pruned;
    }
  }
  return count > 0 ? std::sqrt(sum_sq / count) : 0.0;
}

// Names of the parameters a refinement frees.
std::vector<std::string> FreeParameterNames(const CalibrationRefinementOptions& refinement) {
  std::vector<std::string> names;
  if (refinement.RefinesIntrinsics()) {
    for (const char* camera : {"cam0.", "cam1."}) {
      for (int i = 0; i < UnifiedIntrinsics::kNumParams; ++i) {
        if (!refinement.fixed_intrinsics[i]) {
          names.push_back(std::string(camera) + UnifiedIntrinsics::kNames[i]);
        }
      }
    }
  }
  if (refinement.RefinesRig()) {
    names.push_back("cam0_from_cam1.rotation");
  }
  return names;
}

// Whether the problem is large enough to refine the calibration; otherwise sets the reason.
bool RefinementPossible(const CalibrationRefinementOptions& refinement,
                        const FrameFlags& free_frames, const std::vector<int>& candidates,
                        const SlamMap& map, CalibrationRefinementReport* calibration) {
  std::set<int> frames;
  for (int id : candidates) {
    for (const Observation& o : map.landmarks[id].observations) {
      if (!map.has_pose[o.frame]) continue;
      frames.insert(o.frame);
      ++calibration->num_observations[o.camera];
    }
  }
  calibration->num_frames = static_cast<int>(frames.size());
  int num_free = 0;
  for (char f : free_frames) num_free += f ? 1 : 0;
  std::ostringstream why;
  if (calibration->num_frames < refinement.min_frames || num_free == 0) {
    why << "too few rig positions to refine the calibration (" << calibration->num_frames
        << ", need " << refinement.min_frames << ")";
  } else {
    for (int c = 0; c < 2; ++c) {
      if (calibration->num_observations[c] >= refinement.min_observations_per_camera) continue;
      why << "too few observations in cam" << c << " to refine the calibration ("
          << calibration->num_observations[c] << ", need "
          << refinement.min_observations_per_camera << ")";
      break;
    }
  }
  calibration->reason = why.str();
  return calibration->reason.empty();
}

// BundleAdjust() and BundleAdjustWithCalibration(): `refinement` null keeps the calibration.
BundleAdjustmentReport Adjust(const CalibrationRefinementOptions* refinement,
                              const std::vector<int>& free_frames,
                              const BundleAdjustmentOptions& options, StereoRig* rig,
                              SlamMap* map, CalibrationRefinementReport* calibration,
                              const ProgressSink& progress) {
  options.Check();
  progress.ThrowIfCancelled();
  const Timer timer;
  BundleAdjustmentReport report;
  FrameFlags free_set(map->has_pose.size(), 0);
  bool any_free = false;
  for (int frame : free_frames) {
    OMNIRIG_CHECK(frame >= 0 && frame < static_cast<int>(map->has_pose.size()),
                  "bundle adjustment of unknown frame " << frame);
    if (map->has_pose[frame]) free_set[frame] = any_free = true;
  }
  // One scan of the whole map; the solves and prunings below visit only these landmarks.
  std::vector<int> candidates;
  for (size_t id = 0; any_free && id < map->landmarks.size(); ++id) {
    if (Adjustable(map->landmarks[id], free_set, *map)) candidates.push_back(static_cast<int>(id));
  }
  if (refinement && refinement->refine != CalibrationRefinement::kNone &&
      RefinementPossible(*refinement, free_set, candidates, *map, calibration)) {
    calibration->applied = true;
    calibration->free_parameters = FreeParameterNames(*refinement);
  } else {
    refinement = nullptr;
  }
  if (!any_free) return report;
  report.initial_rms_px = RmsAndPrune(*rig, free_set, candidates, 0, false, map, &report);
  ceres::Solver::Summary summary =
      SolveOnce(refinement, free_set, candidates, options, options.max_iterations, progress, 0,
                rig, map, &report);
  report.iterations = static_cast<int>(summary.iterations.size());
  RmsAndPrune(*rig, free_set, candidates, options.max_reprojection_error_px, true, map, &report);
  // A second, shorter solve without the pruned outliers' pull, when they were more than a few:
  // under the robust loss a handful of outliers barely moves the solution.
  const int num_observations = report.num_residuals / 2;
  if (report.num_observations_pruned > std::max(10, num_observations / 500)) {
    summary = SolveOnce(refinement, free_set, candidates, options, SecondSolveIterations(options),
                        progress, report.iterations, rig, map, &report);
    report.iterations += static_cast<int>(summary.iterations.size());
  }
  report.final_rms_px = RmsAndPrune(*rig, free_set, candidates, 0, false, map, &report);
  report.linear_solver = ceres::LinearSolverTypeToString(summary.linear_solver_type_used);
  report.termination = ceres::TerminationTypeToString(summary.termination_type);
  report.time_s = timer.ElapsedSeconds();
  return report;
}

}  // namespace

RigReprojectionCost::RigReprojectionCost(const UnifiedIntrinsics& intrinsics,
                                         const Rigid3d& cam_from_rig,
                                         const Eigen::Vector2d& observed_pixel)
    : intrinsics_(intrinsics),
      cam_from_rig_rotation_(cam_from_rig.RotationMatrix()),
      cam_from_rig_translation_(cam_from_rig.translation),
      observed_pixel_(observed_pixel) {}

namespace {

// point_in_rig = rig_from_world * x for the pose block [qx, qy, qz, qw, tx, ty, tz], with its
// Jacobians (3x7 and 3x3; either may be null). Eigen's q * x for a possibly non-unit q:
// x + 2w (v × x) + 2 v × (v × x); the Jacobians differentiate exactly this expression.
Eigen::Vector3d RigPoint(const double* pose, const double* point,
                         Eigen::Matrix<double, 3, 7>* d_rig_d_pose,
                         Eigen::Matrix3d* d_rig_d_point) {
  const Eigen::Map<const Eigen::Vector3d> v(pose);  // quaternion's vector part
  const double w = pose[3];
  const Eigen::Map<const Eigen::Vector3d> t(pose + 4);
  const Eigen::Map<const Eigen::Vector3d> x(point);
  const Eigen::Vector3d uv = 2.0 * v.cross(x);
  if (d_rig_d_pose) {
    d_rig_d_pose->leftCols<3>() =
        -2.0 * w * Skew(x) +
        2.0 * (v * x.transpose() + v.dot(x) * Eigen::Matrix3d::Identity() - 2.0 * x * v.transpose());
    d_rig_d_pose->col(3) = uv;
    d_rig_d_pose->rightCols<3>().setIdentity();
  }
  if (d_rig_d_point) {
    *d_rig_d_point = Eigen::Matrix3d::Identity() + 2.0 * w * Skew(v) + 2.0 * Skew(v) * Skew(v);
  }
  return x + w * uv + v.cross(uv) + t;
}

// cam1's point_in_cam = q^-1 (point_in_rig - t) for cam0_from_cam1 = (q, t), with its
// Jacobian over [q (4), t (3), point_in_rig (3)] from 10-dim jets (cheap next to projecting).
Eigen::Vector3d Cam1Point(const double* rotation, const double* translation,
                          const Eigen::Vector3d& point_in_rig,
                          Eigen::Matrix<double, 3, 10>* jacobian) {
  using Jet10 = ceres::Jet<double, 10>;
  Eigen::Quaternion<Jet10> q;
  Eigen::Matrix<Jet10, 3, 1> t, p;
  for (int i = 0; i < 4; ++i) q.coeffs()[i] = Jet10(rotation[i], i);
  for (int i = 0; i < 3; ++i) {
    t[i] = Jet10(translation[i], 4 + i);
    p[i] = Jet10(point_in_rig[i], 7 + i);
  }
  const Eigen::Matrix<Jet10, 3, 1> c = q.conjugate() * (p - t);
  Eigen::Vector3d point_in_cam;
  for (int i = 0; i < 3; ++i) {
    point_in_cam[i] = c[i].a;
    jacobian->row(i) = c[i].v.transpose();
  }
  return point_in_cam;
}

// d pixel / d intrinsics (2x11, row-major into `jacobian`). The linear parameters in closed
// form: pixel = (gamma_u (m_x + alpha m_y) + u0, gamma_v m_y + v0) of the distorted point m;
// xi and k1..k5 by 11-dim jets when `nonlinear_free`, else left zero.
bool IntrinsicsJacobian(const UnifiedIntrinsics& intrinsics, const Eigen::Vector3d& point_in_cam,
                        const Eigen::Vector2d& pixel, bool nonlinear_free, double* jacobian) {
  using I = UnifiedIntrinsics;
  Eigen::Map<Eigen::Matrix<double, 2, I::kNumParams, Eigen::RowMajor>> j(jacobian);
  if (nonlinear_free) {
    using Jet11 = ceres::Jet<double, I::kNumParams>;
    Jet11 params[I::kNumParams], point[3], projected[2];
    for (int i = 0; i < I::kNumParams; ++i) params[i] = Jet11(intrinsics.params[i], i);
    for (int i = 0; i < 3; ++i) point[i] = Jet11(point_in_cam[i]);
    if (!ProjectToPixel(params, point, projected)) return false;
    for (int r = 0; r < 2; ++r) j.row(r) = projected[r].v.transpose();
    return true;
  }
  j.setZero();
  const double my = (pixel.y() - intrinsics.v0()) / intrinsics.gamma_v();
  const double mx = (pixel.x() - intrinsics.u0()) / intrinsics.gamma_u() - intrinsics.alpha() * my;
  j(0, I::kGammaU) = mx + intrinsics.alpha() * my;
  j(0, I::kU0) = 1.0;
  j(0, I::kAlpha) = intrinsics.gamma_u() * my;
  j(1, I::kGammaV) = my;
  j(1, I::kV0) = 1.0;
  return true;
}

}  // namespace

bool RigReprojectionCost::Evaluate(double const* const* parameters, double* residuals,
                                   double** jacobians) const {
  Eigen::Matrix<double, 3, 7> d_rig_d_pose;
  Eigen::Matrix3d d_rig_d_x;
  const Eigen::Vector3d point_in_rig =
      RigPoint(parameters[0], parameters[1], jacobians && jacobians[0] ? &d_rig_d_pose : nullptr,
               jacobians && jacobians[1] ? &d_rig_d_x : nullptr);
  const Eigen::Vector3d point_in_cam = cam_from_rig_rotation_ * point_in_rig +
                                       cam_from_rig_translation_;
  Eigen::Matrix<double, 2, 3> d_pixel_d_cam;
  const std::optional<Eigen::Vector2d> pixel =
      ProjectWithJacobian(intrinsics_, point_in_cam, jacobians ? &d_pixel_d_cam : nullptr);
  if (!pixel) return false;
  residuals[0] = pixel->x() - observed_pixel_.x();
  residuals[1] = pixel->y() - observed_pixel_.y();
  if (!jacobians) return true;
  const Eigen::Matrix<double, 2, 3> d_pixel_d_rig = d_pixel_d_cam * cam_from_rig_rotation_;
  if (jacobians[0]) {
    Eigen::Map<Eigen::Matrix<double, 2, 7, Eigen::RowMajor>> j0(jacobians[0]);
    j0 = d_pixel_d_rig * d_rig_d_pose;
  }
  if (jacobians[1]) {
    Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> j1(jacobians[1]);
    j1 = d_pixel_d_rig * d_rig_d_x;
  }
  return true;
}

RigCalibrationCost::RigCalibrationCost(int camera, const Eigen::Vector2d& observed_pixel,
                                       bool nonlinear_intrinsics_free)
    : camera_(camera),
      observed_pixel_(observed_pixel),
      nonlinear_intrinsics_free_(nonlinear_intrinsics_free) {
  set_num_residuals(2);
  *mutable_parameter_block_sizes() = camera == 0 ? std::vector<int32_t>{7, 3, 11}
                                                 : std::vector<int32_t>{7, 3, 11, 4, 3};
}

bool RigCalibrationCost::Evaluate(double const* const* parameters, double* residuals,
                                  double** jacobians) const {
  using I = UnifiedIntrinsics;
  const bool want = jacobians != nullptr;
  Eigen::Matrix<double, 3, 7> d_rig_d_pose;
  Eigen::Matrix3d d_rig_d_x;
  const Eigen::Vector3d point_in_rig =
      RigPoint(parameters[0], parameters[1], want && jacobians[0] ? &d_rig_d_pose : nullptr,
               want && jacobians[1] ? &d_rig_d_x : nullptr);
  // d_cam_d_transform: [q (4), t (3), point_in_rig (3)]
  Eigen::Matrix<double, 3, 10> d_cam_d_transform;
  const Eigen::Vector3d point_in_cam =
      camera_ == 0 ? point_in_rig
                   : Cam1Point(parameters[3], parameters[4], point_in_rig, &d_cam_d_transform);
  if (camera_ == 0) {
    d_cam_d_transform.setZero();
    d_cam_d_transform.rightCols<3>().setIdentity();
  }
  I intrinsics;
  std::copy(parameters[2], parameters[2] + I::kNumParams, intrinsics.params.begin());
  Eigen::Matrix<double, 2, 3> d_pixel_d_cam;
  const std::optional<Eigen::Vector2d> pixel =
      ProjectWithJacobian(intrinsics, point_in_cam, want ? &d_pixel_d_cam : nullptr);
  if (!pixel) return false;
  residuals[0] = pixel->x() - observed_pixel_.x();
  residuals[1] = pixel->y() - observed_pixel_.y();
  if (!want) return true;
  const Eigen::Matrix<double, 2, 3> d_pixel_d_rig =
      d_pixel_d_cam * d_cam_d_transform.rightCols<3>();
  if (jacobians[0]) {
    Eigen::Map<Eigen::Matrix<double, 2, 7, Eigen::RowMajor>> j0(jacobians[0]);
    j0 = d_pixel_d_rig * d_rig_d_pose;
  }
  if (jacobians[1]) {
    Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> j1(jacobians[1]);
    j1 = d_pixel_d_rig * d_rig_d_x;
  }
  if (jacobians[2]) {
    if (!IntrinsicsJacobian(intrinsics, point_in_cam, *pixel, nonlinear_intrinsics_free_,
                            jacobians[2])) {
      return false;
    }
  }
  if (camera_ == 1 && jacobians[3]) {
    Eigen::Map<Eigen::Matrix<double, 2, 4, Eigen::RowMajor>> j3(jacobians[3]);
    j3 = d_pixel_d_cam * d_cam_d_transform.leftCols<4>();
  }
  if (camera_ == 1 && jacobians[4]) {
    Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> j4(jacobians[4]);
    j4 = d_pixel_d_cam * d_cam_d_transform.middleCols<3>(4);
  }
  return true;
}

Rigid3d CamFromRig(const StereoRig& rig, int camera) {
  OMNIRIG_CHECK(camera == 0 || camera == 1, "a stereo rig has cameras 0 and 1, not " << camera);
  return camera == 0 ? Rigid3d() : rig.cam0_from_cam1.Inverse();
}

const char* CalibrationRefinementName(CalibrationRefinement refine) {
  switch (refine) {
    case CalibrationRefinement::kNone: return "none";
    case CalibrationRefinement::kIntrinsics: return "intrinsics";
    case CalibrationRefinement::kRig: return "rig";
    case CalibrationRefinement::kAll: return "all";
  }
  return "none";
}

void CalibrationRefinementOptions::Check() const {
  OMNIRIG_CHECK(!RefinesIntrinsics() ||
                    std::count(fixed_intrinsics.begin(), fixed_intrinsics.end(), false) > 0,
                "refining the intrinsics needs at least one free intrinsic parameter");
  OMNIRIG_CHECK(min_frames >= 2, "calibration refinement needs min_frames >= 2");
  OMNIRIG_CHECK(min_observations_per_camera >= 1,
                "calibration refinement needs min_observations_per_camera >= 1");
}

void BundleAdjustmentOptions::Check() const {
  OMNIRIG_CHECK(huber_scale_px > 0, "huber_scale_px must be positive");
  OMNIRIG_CHECK(max_reprojection_error_px > 0, "max_reprojection_error_px must be positive");
  OMNIRIG_CHECK(max_iterations > 0, "max_iterations must be positive");
  OMNIRIG_CHECK(num_threads > 0, "num_threads must be positive");
  OMNIRIG_CHECK(max_dense_schur_poses >= 0, "max_dense_schur_poses must not be negative");
}

BundleAdjustmentReport BundleAdjust(const StereoRig& rig, const std::vector<int>& free_frames,
                                    const BundleAdjustmentOptions& options, SlamMap* map,
                                    const ProgressSink& progress) {
  StereoRig unchanged = rig;
  return Adjust(nullptr, free_frames, options, &unchanged, map, nullptr, progress);
}

BundleAdjustmentReport BundleAdjustWithCalibration(
    const CalibrationRefinementOptions& refinement, const std::vector<int>& free_frames,
    const BundleAdjustmentOptions& options, StereoRig* rig, SlamMap* map,
    CalibrationRefinementReport* calibration, const ProgressSink& progress) {
  refinement.Check();
  *calibration = CalibrationRefinementReport();
  calibration->refine = refinement.refine;
  calibration->before = *rig;
  const BundleAdjustmentReport report =
      Adjust(&refinement, free_frames, options, rig, map, calibration, progress);
  calibration->after = *rig;
  return report;
}

Rigid3d RefineRigPose(const StereoRig& rig, const Rigid3d& rig_from_world_init,
                      const std::vector<Observation>& observations,
                      const std::vector<Eigen::Vector3d>& points_in_world,
                      const BundleAdjustmentOptions& options, std::vector<bool>* inliers) {
  options.Check();
  OMNIRIG_CHECK(observations.size() == points_in_world.size(),
                "RefineRigPose needs one point per observation");
  const Rigid3d cam_from_rig[2] = {CamFromRig(rig, 0), CamFromRig(rig, 1)};
  std::array<double, 7> pose = rig_from_world_init.ToParams();
  inliers->assign(observations.size(), true);
  for (int round = 0; round < 2; ++round) {
    ceres::Problem::Options problem_options;
    problem_options.manifold_ownership = ceres::TAKE_OWNERSHIP;
    ceres::Problem problem(problem_options);
    problem.AddParameterBlock(pose.data(), 7, NewPoseManifold());
    std::vector<std::array<double, 3>> points(points_in_world.size());
    ceres::LossFunction* loss = new ceres::HuberLoss(options.huber_scale_px);
    int used = 0;
    for (size_t i = 0; i < observations.size(); ++i) {
      if (!(*inliers)[i]) continue;
      points[i] = {points_in_world[i].x(), points_in_world[i].y(), points_in_world[i].z()};
      const Observation& o = observations[i];
      const CameraModel& camera = o.camera == 0 ? rig.cam0 : rig.cam1;
      problem.AddResidualBlock(
          new RigReprojectionCost(camera.intrinsics, cam_from_rig[o.camera], o.pixel), loss,
          pose.data(), points[i].data());
      problem.SetParameterBlockConstant(points[i].data());
      ++used;
    }
    if (used == 0) {
      delete loss;
      break;
    }
    ceres::Solver::Options solver;
    solver.linear_solver_type = ceres::DENSE_QR;
    solver.max_num_iterations = options.max_iterations;
    solver.logging_type = ceres::SILENT;
    ceres::Solver::Summary summary;
    ceres::Solve(solver, &problem, &summary);
    const Rigid3d refined = Rigid3d::FromParams(pose.data());
    const double max_sq = options.max_reprojection_error_px * options.max_reprojection_error_px;
    for (size_t i = 0; i < observations.size(); ++i) {
      const std::optional<double> e2 =
          SquaredError(rig, refined, points_in_world[i], observations[i]);
      (*inliers)[i] = e2 && *e2 <= max_sq;
    }
  }
  return Rigid3d::FromParams(pose.data());
}

}  // namespace omnirig::slam
