#include "engine/slam/bundle_adjustment.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>
#include <set>
#include <sstream>

#include "engine/geometry/ceres_problem.h"
#include "engine/geometry/reprojection_cost.h"
#include "engine/util/check.h"
#include "engine/util/option_check.h"
#include "engine/util/timer.h"

namespace omnirig::slam {
namespace {

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
};

// One observation's residual: the fixed-calibration cost, or the one over the calibration
// blocks too.
void AddObservation(const StereoRig& rig, const Rigid3d (&cam_from_rig)[2],
                    CalibrationBlocks* calibration, const Observation& o, double* pose,
                    double* point, ceres::LossFunction* loss, ceres::Problem* problem) {
  if (calibration == nullptr) {
    const CameraModel& camera = o.camera == 0 ? rig.cam0 : rig.cam1;
    problem->AddResidualBlock(
        ReprojectionCost::Landmark(o.pixel, cam_from_rig[o.camera], camera.intrinsics), loss,
        pose, point);
  } else if (o.camera == 0) {
    problem->AddResidualBlock(ReprojectionCost::LandmarkWithCalibration(0, o.pixel), loss,
                              {pose, point, calibration->intrinsics[0].data()});
  } else {
    problem->AddResidualBlock(ReprojectionCost::LandmarkWithCalibration(1, o.pixel), loss,
                              {pose, point, calibration->rotation.data(),
                               calibration->translation.data(),
                               calibration->intrinsics[1].data()});
  }
}

// The parameter blocks of one solve: the poses of the frames that see its landmarks, the
// landmarks' points, the calibration when refined, and their elimination order (points first).
struct SolveBlocks {
  std::map<int, std::array<double, 7>> poses;
  std::vector<int> landmark_ids;
  std::vector<std::array<double, 3>> points;  // of landmark_ids, never resized once added
  std::optional<CalibrationBlocks> calibration;
  std::shared_ptr<ceres::ParameterBlockOrdering> ordering =
      std::make_shared<ceres::ParameterBlockOrdering>();
  int num_observations = 0;
};

// Adds the observations of landmark `landmark_ids[i]` from posed frames, and each frame's pose
// the first time it is seen (constant unless the frame is free).
void AddLandmark(const StereoRig& rig, const FrameFlags& free_frames, const SlamMap& map, size_t i,
                 ceres::LossFunction* loss, ceres::Problem* problem, SolveBlocks* blocks) {
  const Rigid3d cam_from_rig[2] = {CamFromRig(rig, 0), CamFromRig(rig, 1)};
  const Landmark& landmark = map.landmarks[blocks->landmark_ids[i]];
  double* point = blocks->points[i].data();
  blocks->points[i] = {landmark.point_in_world.x(), landmark.point_in_world.y(),
                       landmark.point_in_world.z()};
  for (const Observation& o : landmark.observations) {
    if (!map.has_pose[o.frame]) continue;
    auto [it, inserted] =
        blocks->poses.try_emplace(o.frame, map.rig_from_world[o.frame].ToParams());
    double* pose = it->second.data();
    if (inserted) {
      problem->AddParameterBlock(pose, 7, NewPoseManifold());
      blocks->ordering->AddElementToGroup(pose, 1);
      if (!free_frames[o.frame]) problem->SetParameterBlockConstant(pose);
    }
    AddObservation(rig, cam_from_rig, blocks->calibration ? &*blocks->calibration : nullptr, o,
                   pose, point, loss, problem);
    ++blocks->num_observations;
  }
  if (problem->HasParameterBlock(point)) blocks->ordering->AddElementToGroup(point, 0);
}

// Writes a solve's poses, points and calibration back to the map and the rig.
void WriteBack(const SolveBlocks& blocks, StereoRig* rig, SlamMap* map) {
  for (const auto& [frame, params] : blocks.poses) {
    map->rig_from_world[frame] = Rigid3d::FromParams(params.data());
  }
  for (size_t i = 0; i < blocks.landmark_ids.size(); ++i) {
    const std::array<double, 3>& point = blocks.points[i];
    map->landmarks[blocks.landmark_ids[i]].point_in_world =
        Eigen::Vector3d(point[0], point[1], point[2]);
  }
  if (blocks.calibration) blocks.calibration->WriteTo(rig);
}

// One build-and-solve of the problem described at BundleAdjust(); writes the solution back,
// the calibration too when `refinement` is given.
ceres::Solver::Summary SolveOnce(const CalibrationRefinementOptions* refinement,
                                 const FrameFlags& free_frames, const std::vector<int>& candidates,
                                 const BundleAdjustmentOptions& options, int max_iterations,
                                 const ProgressSink& progress, int iteration_offset,
                                 StereoRig* rig, SlamMap* map, BundleAdjustmentReport* report) {
  SolveBlocks blocks;
  for (int id : candidates) {
    if (Adjustable(map->landmarks[id], free_frames, *map)) blocks.landmark_ids.push_back(id);
  }
  blocks.points.resize(blocks.landmark_ids.size());
  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  ceres::LossFunction* loss = new ceres::HuberLoss(options.huber_scale_px);
  if (refinement) {
    blocks.calibration.emplace(*rig);
    blocks.calibration->AddTo(*refinement, &problem, blocks.ordering.get());
  }
  for (size_t i = 0; i < blocks.landmark_ids.size(); ++i) {
    AddLandmark(*rig, free_frames, *map, i, loss, &problem, &blocks);
  }
  FixGauge(free_frames, &blocks.poses, &problem, report);
  report->num_points = static_cast<int>(blocks.landmark_ids.size());
  report->num_residuals = 2 * blocks.num_observations;

  ceres::Solver::Summary summary;
  if (blocks.num_observations == 0) {
    delete loss;  // the problem owns only loss functions it was given
    return summary;
  }
  ceres::Solver::Options solver = MakeSolverOptions(
      SolverSetup(report->num_free_poses, max_iterations, options.num_threads)
          .DenseSchurUpTo(options.max_dense_schur_poses));
  solver.linear_solver_ordering = blocks.ordering;
  // Iterations are counted from `iteration_offset` out of the solves of one adjustment.
  const int budget = options.max_iterations + SecondSolveIterations(options);
  SolverProgress callback(progress, "bundle_adjustment", [&](int iteration) {
    return std::min(1.0, (iteration_offset + iteration) / static_cast<double>(budget));
  });
  solver.callbacks.push_back(&callback);
  ceres::Solve(solver, &problem, &summary);
  progress.ThrowIfCancelled();
  WriteBack(blocks, rig, map);
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

// BundleAdjust() and BundleAdjustWithCalibration(): `refinement` null keeps the calibration;
// `landmark_ids` null scans the whole map.
BundleAdjustmentReport Adjust(const CalibrationRefinementOptions* refinement,
                              const std::vector<int>& free_frames,
                              const std::vector<int>* landmark_ids,
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
  if (landmark_ids) {
    for (int id : *landmark_ids) {
      OMNIRIG_CHECK(id >= 0 && id < static_cast<int>(map->landmarks.size()),
                    "bundle adjustment of unknown landmark " << id);
      if (Adjustable(map->landmarks[id], free_set, *map)) candidates.push_back(id);
    }
  }
  for (size_t id = 0; !landmark_ids && any_free && id < map->landmarks.size(); ++id) {
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
  report.solver = Summarize(summary);
  RmsAndPrune(*rig, free_set, candidates, options.max_reprojection_error_px, true, map, &report);
  // A second, shorter solve without the pruned outliers' pull, when they were more than a few:
  // under the robust loss a handful of outliers barely moves the solution.
  const int num_observations = report.num_residuals / 2;
  if (report.num_observations_pruned > std::max(10, num_observations / 500)) {
    summary = SolveOnce(refinement, free_set, candidates, options, SecondSolveIterations(options),
                        progress, report.solver.num_iterations, rig, map, &report);
    const SolverSummary second = Summarize(summary);
    report.solver.num_iterations += second.num_iterations;
    report.solver.final_cost = second.final_cost;
    report.solver.usable = second.usable;
  }
  report.final_rms_px = RmsAndPrune(*rig, free_set, candidates, 0, false, map, &report);
  report.linear_solver = ceres::LinearSolverTypeToString(summary.linear_solver_type_used);
  report.solver.termination = ceres::TerminationTypeToString(summary.termination_type);
  report.solver.time_s = timer.ElapsedSeconds();  // both solves and the RMS passes
  return report;
}

}  // namespace

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
  OMNIRIG_CHECK_AT_LEAST(min_frames, 2);
  OMNIRIG_CHECK_AT_LEAST(min_observations_per_camera, 1);
}

void BundleAdjustmentOptions::Check() const {
  OMNIRIG_CHECK_POSITIVE(huber_scale_px);
  OMNIRIG_CHECK_POSITIVE(max_reprojection_error_px);
  OMNIRIG_CHECK_POSITIVE(max_iterations);
  OMNIRIG_CHECK_POSITIVE(num_threads);
  OMNIRIG_CHECK_NON_NEGATIVE(max_dense_schur_poses);
}

BundleAdjustmentReport BundleAdjust(const StereoRig& rig, const std::vector<int>& free_frames,
                                    const BundleAdjustmentOptions& options, SlamMap* map,
                                    const ProgressSink& progress) {
  StereoRig unchanged = rig;
  return Adjust(nullptr, free_frames, nullptr, options, &unchanged, map, nullptr, progress);
}

BundleAdjustmentReport BundleAdjustLandmarks(const StereoRig& rig,
                                             const std::vector<int>& free_frames,
                                             const std::vector<int>& landmark_ids,
                                             const BundleAdjustmentOptions& options, SlamMap* map,
                                             const ProgressSink& progress) {
  StereoRig unchanged = rig;
  return Adjust(nullptr, free_frames, &landmark_ids, options, &unchanged, map, nullptr, progress);
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
      Adjust(&refinement, free_frames, nullptr, options, rig, map, calibration, progress);
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
          ReprojectionCost::Landmark(o.pixel, cam_from_rig[o.camera], camera.intrinsics), loss,
          pose.data(), points[i].data());
      problem.SetParameterBlockConstant(points[i].data());
      ++used;
    }
    if (used == 0) {
      delete loss;
      break;
    }
    const ceres::Solver::Options solver = MakeSolverOptions(SolverSetup(0, options.max_iterations));
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
