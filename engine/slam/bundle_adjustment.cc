#include "engine/slam/bundle_adjustment.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <set>

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

// One build-and-solve of the problem described at BundleAdjust(); writes the solution back.
ceres::Solver::Summary SolveOnce(const StereoRig& rig, const FrameFlags& free_frames,
                                 const std::vector<int>& candidates,
                                 const BundleAdjustmentOptions& options, int max_iterations,
                                 const ProgressSink& progress, int iteration_offset, SlamMap* map,
                                 BundleAdjustmentReport* report) {
  std::map<int, std::array<double, 7>> poses;
  std::vector<int> landmark_ids;
  for (int id : candidates) {
    if (Adjustable(map->landmarks[id], free_frames, *map)) landmark_ids.push_back(id);
  }
  std::vector<std::array<double, 3>> points(landmark_ids.size());
  const Rigid3d cam_from_rig[2] = {CamFromRig(rig, 0), CamFromRig(rig, 1)};

  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  ceres::LossFunction* loss = new ceres::HuberLoss(options.huber_scale_px);
  auto ordering = std::make_shared<ceres::ParameterBlockOrdering>();
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
      const CameraModel& camera = o.camera == 0 ? rig.cam0 : rig.cam1;
      problem.AddResidualBlock(
          new RigReprojectionCost(camera.intrinsics, cam_from_rig[o.camera], o.pixel), loss,
          it->second.data(), points[i].data());
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

}  // namespace

RigReprojectionCost::RigReprojectionCost(const UnifiedIntrinsics& intrinsics,
                                         const Rigid3d& cam_from_rig,
                                         const Eigen::Vector2d& observed_pixel)
    : intrinsics_(intrinsics),
      cam_from_rig_rotation_(cam_from_rig.RotationMatrix()),
      cam_from_rig_translation_(cam_from_rig.translation),
      observed_pixel_(observed_pixel) {}

bool RigReprojectionCost::Evaluate(double const* const* parameters, double* residuals,
                                   double** jacobians) const {
  const double* pose = parameters[0];
  const Eigen::Map<const Eigen::Vector3d> v(pose);  // quaternion's vector part
  const double w = pose[3];
  const Eigen::Map<const Eigen::Vector3d> t(pose + 4);
  const Eigen::Map<const Eigen::Vector3d> x(parameters[1]);
  // Eigen's q * x for a possibly non-unit q: x + 2w (v × x) + 2 v × (v × x). The Jacobians
  // below differentiate exactly this expression.
  const Eigen::Vector3d uv = 2.0 * v.cross(x);
  const Eigen::Vector3d point_in_rig = x + w * uv + v.cross(uv) + t;
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
    Eigen::Map<Eigen::Matrix<double, 2, 7, Eigen::RowMajor>> j(jacobians[0]);
    const Eigen::Matrix3d d_rig_d_v =
        -2.0 * w * Skew(x) +
        2.0 * (v * x.transpose() + v.dot(x) * Eigen::Matrix3d::Identity() - 2.0 * x * v.transpose());
    j.leftCols<3>() = d_pixel_d_rig * d_rig_d_v;
    j.col(3) = d_pixel_d_rig * (2.0 * v.cross(x));
    j.rightCols<3>() = d_pixel_d_rig;
  }
  if (jacobians[1]) {
    const Eigen::Matrix3d d_rig_d_x = Eigen::Matrix3d::Identity() + 2.0 * w * Skew(v) +
                                      2.0 * Skew(v) * Skew(v);
    Eigen::Map<Eigen::Matrix<double, 2, 3, Eigen::RowMajor>> j(jacobians[1]);
    j = d_pixel_d_rig * d_rig_d_x;
  }
  return true;
}

Rigid3d CamFromRig(const StereoRig& rig, int camera) {
  OMNIRIG_CHECK(camera == 0 || camera == 1, "a stereo rig has cameras 0 and 1, not " << camera);
  return camera == 0 ? Rigid3d() : rig.cam0_from_cam1.Inverse();
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
  if (!any_free) return report;
  // One scan of the whole map; the solves and prunings below visit only these landmarks.
  std::vector<int> candidates;
  for (size_t id = 0; id < map->landmarks.size(); ++id) {
    if (Adjustable(map->landmarks[id], free_set, *map)) candidates.push_back(static_cast<int>(id));
  }
  report.initial_rms_px = RmsAndPrune(rig, free_set, candidates, 0, false, map, &report);
  ceres::Solver::Summary summary =
      SolveOnce(rig, free_set, candidates, options, options.max_iterations, progress, 0, map,
                &report);
  report.iterations = static_cast<int>(summary.iterations.size());
  RmsAndPrune(rig, free_set, candidates, options.max_reprojection_error_px, true, map, &report);
  // A second, shorter solve without the pruned outliers' pull, when they were more than a few:
  // under the robust loss a handful of outliers barely moves the solution.
  const int num_observations = report.num_residuals / 2;
  if (report.num_observations_pruned > std::max(10, num_observations / 500)) {
    summary = SolveOnce(rig, free_set, candidates, options,
                        SecondSolveIterations(options), progress, report.iterations, map, &report);
    report.iterations += static_cast<int>(summary.iterations.size());
  }
  report.final_rms_px = RmsAndPrune(rig, free_set, candidates, 0, false, map, &report);
  report.linear_solver = ceres::LinearSolverTypeToString(summary.linear_solver_type_used);
  report.termination = ceres::TerminationTypeToString(summary.termination_type);
  report.time_s = timer.ElapsedSeconds();
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
