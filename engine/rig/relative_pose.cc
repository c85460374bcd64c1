#include "engine/rig/relative_pose.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <iomanip>
#include <optional>
#include <set>
#include <sstream>
#include <utility>

#include "engine/estimators/board_pose.h"
#include "engine/rig/relpose_corner_order.h"
#include "engine/rig/relpose_linear.h"
#include "engine/rig/relpose_refine.h"
#include "engine/util/option_check.h"

namespace omnirig {

void RelativePoseOptions::Check() const {
  OMNIRIG_CHECK_IN(consensus_rotation_deg, '(', 0, 90, ')');
  OMNIRIG_CHECK_IN(consensus_translation_fraction, '(', 0, 1, ')');
  OMNIRIG_CHECK_POSITIVE(max_board_pose_rms_px);
  sync_test.Check();
  OMNIRIG_CHECK_NON_NEGATIVE(huber_loss_px);
  OMNIRIG_CHECK_IN(max_num_iterations, '[', 1, 10000, ']');
  OMNIRIG_CHECK_AT_LEAST(num_threads, 1);
  OMNIRIG_CHECK_AT_LEAST(min_num_pairs, 1);
  OMNIRIG_CHECK_IN(min_spread_eigen_ratio, '[', 0, 1, ')');
}

RigRefinementOptions RelativePoseOptions::RefinementOptions() const {
  RigRefinementOptions refine;
  refine.refine_intrinsics = refine_intrinsics;
  refine.fixed_intrinsics = fixed_intrinsics;
  refine.cam1_fixed_intrinsics = cam1_fixed_intrinsics;
  refine.huber_loss_px = huber_loss_px;
  refine.max_num_iterations = max_num_iterations;
  refine.num_threads = num_threads;
  return refine;
}

namespace {

// One pair's board poses as estimated per camera, before the corner order is settled.
struct PairPoses {
  bool ok = false;
  Rigid3d cam0_from_board;
  Rigid3d cam1_from_board_as_detected;
  double board_distance_m = 0.0;
  std::vector<Rigid3d> candidates;  // cam0_from_cam1 per corner order (BoardSymmetry)
};

std::vector<Eigen::Vector3d> PointsOf(const std::vector<Eigen::Vector3d>& object_points,
                                      const std::vector<int>& ids) {
  std::vector<Eigen::Vector3d> points;
  points.reserve(ids.size());
  for (int id : ids) points.push_back(object_points[id]);
  return points;
}

std::string NotFoundReason(const StereoBoardPair& pair) {
  if (!pair.cam0.found && !pair.cam1.found) {
    return "board not found in either camera (cam0: " + pair.cam0.reason +
           "; cam1: " + pair.cam1.reason + ")";
  }
  if (!pair.cam0.found) return "board seen by cam1 only (cam0: " + pair.cam0.reason + ")";
  if (!pair.cam1.found) return "board seen by cam0 only (cam1: " + pair.cam1.reason + ")";
  return "";
}

bool ValidIds(const BoardDetection& detection, int num_corners) {
  if (detection.corner_ids.size() != detection.corners_px.size()) return false;
  for (int id : detection.corner_ids) {
    if (id < 0 || id >= num_corners) return false;
  }
  return true;
}

// Step 1 for a single camera's view: the board's pose in that camera (no rig candidates).
PairPoses EstimateSingleViewPose(const CameraModel& cam0, const CameraModel& cam1,
                                 const BoardSpec& board, const StereoBoardPair& view,
                                 const RelativePoseOptions& options,
                                 RelativePosePairReport* report) {
  PairPoses poses;
  const int camera = view.cam0.found ? 0 : 1;
  const BoardDetection& detection = camera == 0 ? view.cam0 : view.cam1;
  if (!detection.found || (view.cam0.found && view.cam1.found)) {
    report->reason = "a single camera's view needs the board found in exactly one camera";
    return poses;
  }
  if (!ValidIds(detection, board.NumCorners())) {
    report->reason = "corner ids do not match the board " + board.Describe();
    return poses;
  }
  double rms = 0.0;
  const auto cam_from_board = EstimateBoardPose(
      camera == 0 ? cam0 : cam1, PointsOf(board.ObjectPoints(), detection.corner_ids),
      detection.corners_px, &rms);
  std::ostringstream reason;
  if (!cam_from_board) {
    reason << "no board pose (the corners do not fit the camera model)";
  } else if (rms > options.max_board_pose_rms_px) {
    reason << "board pose fit too poor (" << rms << " px; limit " << options.max_board_pose_rms_px
           << " px)";
  }
  report->reason = reason.str();
  if (!report->reason.empty()) return poses;
  poses.ok = true;
  (camera == 0 ? poses.cam0_from_board : poses.cam1_from_board_as_detected) = *cam_from_board;
  return poses;
}

// Step 1 for one pair: the board's pose in each camera, then one rig candidate per order.
PairPoses EstimatePairPoses(const CameraModel& cam0, const CameraModel& cam1,
                            const BoardSpec& board, const std::vector<BoardSymmetry>& symmetries,
                            const StereoBoardPair& pair, const RelativePoseOptions& options,
                            RelativePosePairReport* report) {
  if (pair.single_camera_view) {
    return EstimateSingleViewPose(cam0, cam1, board, pair, options, report);
  }
  PairPoses poses;
  report->reason = NotFoundReason(pair);
  if (!report->reason.empty()) return poses;
  if (!ValidIds(pair.cam0, board.NumCorners()) || !ValidIds(pair.cam1, board.NumCorners())) {
    report->reason = "corner ids do not match the board " + board.Describe();
    return poses;
  }
  const std::vector<Eigen::Vector3d> object_points = board.ObjectPoints();
  double rms0 = 0.0, rms1 = 0.0;
  const auto cam0_from_board = EstimateBoardPose(
      cam0, PointsOf(object_points, pair.cam0.corner_ids), pair.cam0.corners_px, &rms0);
  const auto cam1_from_board = EstimateBoardPose(
      cam1, PointsOf(object_points, pair.cam1.corner_ids), pair.cam1.corners_px, &rms1);
  std::ostringstream reason;
  if (!cam0_from_board || !cam1_from_board) {
    reason << "no board pose in " << (!cam0_from_board ? "cam0" : "cam1")
           << " (the corners do not fit the camera model)";
  } else if (rms0 > options.max_board_pose_rms_px || rms1 > options.max_board_pose_rms_px) {
    reason << "board pose fit too poor (cam0 " << rms0 << " px, cam1 " << rms1 << " px; limit "
           << options.max_board_pose_rms_px << " px)";
  }
  report->reason = reason.str();
  if (!report->reason.empty()) return poses;

  poses.ok = true;
  poses.cam0_from_board = *cam0_from_board;
  poses.cam1_from_board_as_detected = *cam1_from_board;
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const auto& p : object_points) centroid += p;
  centroid /= static_cast<double>(object_points.size());
  poses.board_distance_m = (*cam0_from_board * centroid).norm();
  // Detected id `id` really being corner permutation[id] means
  // cam1_from_board = cam1_from_board_as_detected * board_from_board^-1.
  for (const BoardSymmetry& symmetry : symmetries) {
    poses.candidates.push_back(*cam0_from_board * symmetry.board_from_board *
                               cam1_from_board->Inverse());
  }
  return poses;
}

// Step 2's output for one used pair: cam1's ids relabelled, the corners for the refinement and
// the common corners in both cameras' frames for eq. (9).
void BuildPairCorners(const BoardSpec& board, const StereoBoardPair& pair,
                      const BoardSymmetry& symmetry, const PairPoses& poses,
                      RigPairCorners* corners, std::vector<Eigen::Vector3d>* points_in_cam0,
                      std::vector<Eigen::Vector3d>* points_in_cam1, int* num_common) {
  const std::vector<Eigen::Vector3d> object_points = board.ObjectPoints();
  const Rigid3d cam1_from_board =
      poses.cam1_from_board_as_detected * symmetry.board_from_board.Inverse();
  std::set<int> ids0(pair.cam0.corner_ids.begin(), pair.cam0.corner_ids.end());
  corners->points_in_board0 = PointsOf(object_points, pair.cam0.corner_ids);
  corners->pixels0 = pair.cam0.corners_px;
  *num_common = 0;
  for (size_t c = 0; c < pair.cam1.corner_ids.size(); ++c) {
    const int id = symmetry.permutation[pair.cam1.corner_ids[c]];
    corners->points_in_board1.push_back(object_points[id]);
    corners->pixels1.push_back(pair.cam1.corners_px[c]);
    if (ids0.count(id) == 0) continue;
    points_in_cam0->push_back(poses.cam0_from_board * object_points[id]);
    points_in_cam1->push_back(cam1_from_board * object_points[id]);
    ++*num_common;
  }
}

}  // namespace

std::string RelativePoseSummary(const RelativePoseReport& report) {
  const double angle_deg =
      Eigen::AngleAxisd(report.rig.cam0_from_cam1.rotation).angle() * 180.0 / M_PI;
  std::ostringstream os;
  os << std::fixed << std::setprecision(2) << "baseline " << report.baseline_m * 1e3 << " +- "
     << report.baseline_std_m * 1e3 << " mm, rotation " << angle_deg << " deg, "
     << report.num_pairs_used << " of " << report.pairs.size() << " pairs used";
  return os.str();
}

namespace {

std::string UsedPairsMessage(const RelativePoseReport& report) {
  std::ostringstream os;
  os << report.num_pairs_used << " of " << report.pairs.size() << " pairs usable";
  for (const RelativePosePairReport& pair : report.pairs) {
    if (!pair.used) os << "; " << pair.name << ": " << pair.reason;
  }
  return os.str();
}

// The pairs (and single-camera views) that enter the estimate, with what steps 3 and 4 need of
// each.
struct UsedPairs {
  std::vector<size_t> index;       // into the input pairs
  std::vector<int> single_camera;  // per entry: -1 for a pair, the camera of a single view
  // cam1's own board pose of each cam1 view (entry, pose): its cam0_from_board needs the rig.
  std::vector<std::pair<size_t, Rigid3d>> cam1_views;
  std::vector<RigPairCorners> corners;
  std::vector<Rigid3d> cam0_from_board;
  std::vector<Rigid3d> per_pair_rigs;                           // cam0_from_cam1 of each pair alone
  std::vector<Eigen::Vector3d> points_in_cam0, points_in_cam1;  // common corners, eq. (9)
};

// A single camera's view as the refinement takes it: corners on one side only.
RigPairCorners SingleViewCorners(const BoardSpec& board, const StereoBoardPair& view) {
  RigPairCorners corners;
  const std::vector<Eigen::Vector3d> object_points = board.ObjectPoints();
  if (view.cam0.found) {
    corners.points_in_board0 = PointsOf(object_points, view.cam0.corner_ids);
    corners.pixels0 = view.cam0.corners_px;
  } else {
    corners.points_in_board1 = PointsOf(object_points, view.cam1.corner_ids);
    corners.pixels1 = view.cam1.corners_px;
  }
  return corners;
}

// Step 2's bookkeeping: every pair with poses and a consistent order, except those a reason
// excludes; single-camera views with `use_single_views` (the intrinsics are refined).
UsedPairs CollectUsedPairs(const BoardSpec& board, const std::vector<StereoBoardPair>& pairs,
                           const std::vector<BoardSymmetry>& symmetries,
                           const std::vector<PairPoses>& poses, const std::vector<int>& chosen,
                           bool use_single_views, RelativePoseReport* report) {
  UsedPairs used;
  report->num_single_camera_views_used = 0;
  for (size_t i = 0; i < pairs.size(); ++i) {
    RelativePosePairReport& pair_report = report->pairs[i];
    pair_report.used = false;
    if (!poses[i].ok || !pair_report.reason.empty()) continue;
    if (pairs[i].single_camera_view) {
      if (!use_single_views) {
        pair_report.reason =
            "a single camera's view: used only where the intrinsics are refined with the rig";
        continue;
      }
      const int camera = pairs[i].cam0.found ? 0 : 1;
      pair_report.used = true;
      pair_report.num_corners =
          static_cast<int>((camera == 0 ? pairs[i].cam0 : pairs[i].cam1).corners_px.size());
      if (camera == 1)
        used.cam1_views.emplace_back(used.index.size(), poses[i].cam1_from_board_as_detected);
      used.index.push_back(i);
      used.single_camera.push_back(camera);
      used.corners.push_back(SingleViewCorners(board, pairs[i]));
      used.cam0_from_board.push_back(poses[i].cam0_from_board);  // cam1's: set with the rig
      ++report->num_single_camera_views_used;
      continue;
    }
    if (chosen[i] < 0) {
      pair_report.reason =
          "disagrees with the other pairs on the rig pose (board moved between "
          "the two exposures, or wrong corners)";
      continue;
    }
    RigPairCorners corners;
    BuildPairCorners(board, pairs[i], symmetries[chosen[i]], poses[i], &corners,
                     &used.points_in_cam0, &used.points_in_cam1, &pair_report.num_corners);
    pair_report.used = true;
    pair_report.cam1_order = chosen[i];
    used.index.push_back(i);
    used.single_camera.push_back(-1);
    used.corners.push_back(std::move(corners));
    used.cam0_from_board.push_back(poses[i].cam0_from_board);
    used.per_pair_rigs.push_back(poses[i].candidates[chosen[i]]);
  }
  report->num_pairs_used =
      static_cast<int>(used.index.size()) - report->num_single_camera_views_used;
  return used;
}

// Step 3: eq. (9) and the degeneracy test on the same points. False (with the message) when
// the geometry cannot give a confident rig.
bool SolveLinear(const UsedPairs& used, const RelativePoseOptions& options,
                 RelativePoseReport* report) {
  report->averaged_cam0_from_cam1 = AverageRigidPoses(used.per_pair_rigs);
  report->spread_eigen_ratio = SpreadEigenRatio(used.points_in_cam1);
  const std::optional<Rigid3d> linear =
      SolveRelativePoseLinear(used.points_in_cam0, used.points_in_cam1);
  if (linear && report->spread_eigen_ratio >= options.min_spread_eigen_ratio) {
    report->linear_cam0_from_cam1 = *linear;
    return true;
  }
  report->degenerate = true;
  std::ostringstream os;
  os << "degenerate geometry: the board's corners over all " << report->num_pairs_used
     << " used pairs are (nearly) coplanar (spread ratio " << report->spread_eigen_ratio
     << ", need " << options.min_spread_eigen_ratio
     << "), as when every pair shows the board at one pose; move or tilt the board between pairs";
  report->message = os.str();
  return false;
}

// Step 4: the joint refinement, and the per-pair and overall RMS. From the linear estimate,
// or with `warm_start` from the previous round's solution (the rig and the board poses of the
// pairs still used): one pair fewer moves the optimum little, and the refits after each
// rejection then take a few iterations instead of a full solve.
bool SolveJoint(UsedPairs* used, const RigRefinementOptions& refine, bool warm_start,
                const ProgressSink& progress, RelativePoseReport* report) {
  StereoRig rig = report->rig;
  if (warm_start) {
    for (size_t u = 0; u < used->index.size(); ++u) {
      used->cam0_from_board[u] = report->pairs[used->index[u]].cam0_from_board;
    }
  } else {
    rig.cam0_from_cam1 = report->linear_cam0_from_cam1;
    for (const auto& [u, cam1_from_board] : used->cam1_views) {
      used->cam0_from_board[u] = rig.cam0_from_cam1 * cam1_from_board;
    }
  }
  // The uncertainty only of the last round's fit (EstimateRelativePose): each fit before it
  // is refitted without one pair.
  const SolverSummary summary =
      RefineRig(used->corners, refine, &rig, &used->cam0_from_board, nullptr, progress);
  report->solver = summary;
  if (!summary.usable) {
    report->message = "the joint refinement failed (" + summary.termination + ")";
    return false;
  }
  report->rig = rig;
  report->baseline_m = rig.cam0_from_cam1.translation.norm();
  double sum_squares = 0.0;
  size_t count = 0;
  for (size_t u = 0; u < used->index.size(); ++u) {
    RelativePosePairReport& pair_report = report->pairs[used->index[u]];
    pair_report.cam0_from_board = used->cam0_from_board[u];
    pair_report.rms_px = PairRmsPx(rig, used->cam0_from_board[u], used->corners[u]);
    const size_t n = used->corners[u].pixels0.size() + used->corners[u].pixels1.size();
    sum_squares += pair_report.rms_px * pair_report.rms_px * n;
    count += n;
  }
  report->rms_px = count > 0 ? std::sqrt(sum_squares / count) : 0.0;
  return true;
}

// Why a pair flagged by the synchronisation test is left out, in the user's terms.
std::string UnsynchronisedReason(const PairSyncStatistic& pair, const SyncTestReport& test,
                                 size_t num_tested, double false_alarm_rate) {
  std::ostringstream os;
  os.precision(3);
  os << "the cameras disagree on the board's pose by " << pair.board_offset_m * 1e3 << " mm and "
     << pair.board_rotation_deg << " deg at its centre, beyond what corner noise of "
     << std::sqrt(pair.own_variance_px2[0]) << " / " << std::sqrt(pair.own_variance_px2[1])
     << " px (this pair's own fits; " << test.corner_noise_px[0] << " / "
     << test.corner_noise_px[1] << " px over all pairs)";
  if (test.dispersion > 1.0) {
    os << " and the spread common to all pairs (dispersion " << test.dispersion << ")";
  }
  os << " explain (statistic " << pair.statistic << " over the limit " << test.limit << " for "
     << 100.0 * false_alarm_rate << " % false alarms over " << num_tested
     << " pairs): exposures not simultaneous? (or corners wrong in one image)";
  return os.str();
}

// The rigs the synchronisation test judges the pairs by. With the intrinsics refined, the
// estimate's own (none returned). With the cameras kept at their own calibrations, those
// calibrations' errors (systematic, different at every board position, and large against
// corner noise of a few hundredths of a pixel) would count as the pairs' disagreement: on
// synchronised renders of 20 pairs the test then lost 1 to 5 pairs per rig (statistics up to
// 64 against a limit of 24 over 4 seeds of QuickStereoBoardOptions). So each pair is also judged by
// the rig refitted without it, the intrinsics refined (options.fixed_intrinsics held): a camera
// model near the given one that the other pairs support; the test keeps the reference with
// the smaller median statistic. Without the pair, so that its own
// disagreement cannot be absorbed by the intrinsics (refitting with it, a 1 mm move was found
// in 15 of 20 synthetic rigs instead of 19; relpose_sync_power_test.cc); the test expects each
// refit's own error at its pair (TestPairSynchronisation).
HeldOutRigs SyncTestRigs(const std::vector<RigPairCorners>& corners,
                         const RelativePoseOptions& options, const StereoRig& rig,
                         const std::vector<Rigid3d>& cam0_from_board) {
  if (options.refine_intrinsics || options.sync_test.false_alarm_rate == 0.0 ||
      corners.size() < 3) {
    return {};
  }
  RigRefinementOptions refine = options.RefinementOptions();
  refine.refine_intrinsics = true;
  HeldOutRigs held_out;
  held_out.fixed_intrinsics = {refine.fixed_intrinsics,
                               refine.cam1_fixed_intrinsics.value_or(refine.fixed_intrinsics)};
  // Every refit without one pair starts from the fit with all: a few iterations each.
  StereoRig all = rig;
  std::vector<Rigid3d> all_poses = cam0_from_board;
  if (!RefineRig(corners, refine, &all, &all_poses, nullptr).usable) {
    all = rig;
    all_poses = cam0_from_board;
  }
  std::vector<StereoRig>& rigs = held_out.rig_of_pair;
  rigs.assign(corners.size(), rig);
  for (size_t i = 0; i < corners.size(); ++i) {
    std::vector<RigPairCorners> others;
    std::vector<Rigid3d> poses;
    for (size_t j = 0; j < corners.size(); ++j) {
      if (j == i) continue;
      others.push_back(corners[j]);
      poses.push_back(all_poses[j]);
    }
    StereoRig refined = all;
    if (RefineRig(others, refine, &refined, &poses, nullptr).usable) rigs[i] = refined;
  }
  return held_out;
}

// Step 5: the synchronisation test on the used pairs of the current rig (relpose_sync.h); the
// statistics go into the report. With `reject`, the worst flagged pair is marked unused,
// unless that would leave fewer than min_num_pairs or `min_kept` pairs. Returns whether one
// was.
bool TestSynchronisation(const UsedPairs& used, const RelativePoseOptions& options, bool reject,
                         int min_kept, RelativePoseReport* report) {
  std::vector<size_t> tested;  // the entries of `used` that are pairs
  std::vector<RigPairCorners> corners;
  std::vector<Rigid3d> cam0_from_board;
  for (size_t u = 0; u < used.index.size(); ++u) {
    if (used.single_camera[u] >= 0) continue;
    tested.push_back(u);
    corners.push_back(used.corners[u]);
    cam0_from_board.push_back(used.cam0_from_board[u]);
  }
  report->sync_test =
      TestPairSynchronisation(report->rig, corners, cam0_from_board, options.sync_test);
  const HeldOutRigs rigs = SyncTestRigs(corners, options, report->rig, cam0_from_board);
  if (!rigs.rig_of_pair.empty()) {
    // Whichever explains the bulk of the pairs better (the smaller median statistic): the
    // given cameras when they are right (with few pairs the refitted intrinsics are the
    // noisier reference), the refitted ones when the calibrations are off.
    SyncTestReport refitted =
        TestPairSynchronisation(report->rig, corners, cam0_from_board, options.sync_test, rigs);
    if (refitted.run && (!report->sync_test.run ||
                         refitted.median_statistic < report->sync_test.median_statistic)) {
      report->sync_test = std::move(refitted);
    }
  }
  const SyncTestReport& test = report->sync_test;
  if (!test.run) return false;
  for (size_t k = 0; k < tested.size(); ++k) {
    RelativePosePairReport& pair = report->pairs[used.index[tested[k]]];
    const PairSyncStatistic& statistic = test.pairs[k];
    pair.sync_statistic = statistic.valid ? statistic.statistic : -1.0;
    pair.board_offset_m = statistic.valid ? statistic.board_offset_m : -1.0;
    pair.board_rotation_deg = statistic.valid ? statistic.board_rotation_deg : -1.0;
  }
  const int num_left = static_cast<int>(tested.size()) - 1;
  if (!reject || test.worst < 0 || num_left < std::max(options.min_num_pairs, min_kept)) {
    return false;
  }
  RelativePosePairReport& pair = report->pairs[used.index[tested[test.worst]]];
  pair.reason = UnsynchronisedReason(test.pairs[test.worst], test, tested.size(),
                                     options.sync_test.false_alarm_rate);
  pair.rms_px = -1.0;
  return true;
}

// Round r of the joint refinement (the rejection loop's) reports within
// [1 - 0.5^(r+1), 1 - 0.5^(r+2)] of `progress`, which must outlive the sink.
ProgressSink RoundProgress(const ProgressSink& progress, int round) {
  const double start = 1.0 - std::pow(0.5, round + 1), span = std::pow(0.5, round + 2);
  return ProgressSink{[&progress, start, span](double fraction, const std::string& stage,
                                               const std::string& message) {
                        progress.Report(start + span * fraction, stage, message);
                      },
                      progress.is_cancelled};
}

// Steps 1 and 2 for every pair: the board's pose in each camera, the rig candidates per
// corner order, and the order of each pair that makes the pairs agree (-1: none does).
struct PairsWithOrder {
  std::vector<BoardSymmetry> symmetries;
  std::vector<PairPoses> poses;
  std::vector<int> chosen;
};

PairsWithOrder EstimateOrderedPairPoses(const CameraModel& cam0, const CameraModel& cam1,
                                        const BoardSpec& board,
                                        const std::vector<StereoBoardPair>& pairs,
                                        const RelativePoseOptions& options,
                                        const ProgressSink& progress, RelativePoseReport* report) {
  PairsWithOrder ordered;
  ordered.symmetries = BoardGridSymmetries(board);
  if (!options.resolve_corner_order || board.type != BoardSpec::Type::kCheckerboard) {
    ordered.symmetries.resize(1);
  }
  ordered.poses.resize(pairs.size());
  std::vector<std::vector<Rigid3d>> candidates(pairs.size());
  std::vector<double> scales(pairs.size(), 1.0);
  report->pairs.resize(pairs.size());
  for (size_t i = 0; i < pairs.size(); ++i) {
    progress.ThrowIfCancelled();
    report->pairs[i].name = pairs[i].name;
    if (pairs[i].single_camera_view) report->pairs[i].single_camera = pairs[i].cam0.found ? 0 : 1;
    ordered.poses[i] = EstimatePairPoses(cam0, cam1, board, ordered.symmetries, pairs[i], options,
                                         &report->pairs[i]);
    candidates[i] = ordered.poses[i].candidates;
    scales[i] = ordered.poses[i].board_distance_m;
    progress.Report(0.5 * (i + 1.0) / pairs.size(), "board_pose", pairs[i].name);
  }
  ordered.chosen = ChooseConsistentCandidates(candidates, scales, options.consensus_rotation_deg,
                                              options.consensus_translation_fraction);
  return ordered;
}

// The covariance of cam0_from_cam1 in the final fit, into the report.
void SetRigUncertainty(const UsedPairs& used, const RelativePoseOptions& options,
                       RelativePoseReport* report) {
  const RigUncertainty uncertainty = EstimateRigUncertainty(
      used.corners, options.RefinementOptions(), report->rig, used.cam0_from_board);
  report->baseline_std_m = uncertainty.baseline_std_m;
  report->translation_std_m = uncertainty.translation_std_m;
  report->rotation_std_deg = uncertainty.rotation_std_deg;
  if (uncertainty.robust_valid) {
    report->baseline_std_robust_m = uncertainty.robust_baseline_std_m;
    report->rotation_std_robust_deg = uncertainty.robust_rotation_std_deg;
  }
}

}  // namespace

RelativePoseReport EstimateRelativePose(const CameraModel& cam0, const CameraModel& cam1,
                                        const BoardSpec& board,
                                        const std::vector<StereoBoardPair>& pairs,
                                        const RelativePoseOptions& options,
                                        const ProgressSink& progress) {
  options.Check();
  board.Check();
  cam0.intrinsics.Check();
  cam1.intrinsics.Check();
  RelativePoseReport report;
  report.rig.cam0 = cam0;
  report.rig.cam1 = cam1;

  // Steps 1 and 2: board poses per camera, one corner order per pair.
  const PairsWithOrder ordered =
      EstimateOrderedPairPoses(cam0, cam1, board, pairs, options, progress, &report);
  // Steps 3 and 4, again without the pair that step 5 finds least synchronised, until it finds
  // none (at most max_rounds times, and at most half the pairs first used).
  int min_kept = 0;
  UsedPairs used;
  for (int round = 0;; ++round) {
    used = CollectUsedPairs(board, pairs, ordered.symmetries, ordered.poses, ordered.chosen,
                            options.refine_intrinsics, &report);
    if (report.num_pairs_used < options.min_num_pairs) {
      report.message = "too few usable pairs (need " + std::to_string(options.min_num_pairs) +
                       "): " + UsedPairsMessage(report);
      return report;
    }
    if (!SolveLinear(used, options, &report)) return report;
    if (!SolveJoint(&used, options.RefinementOptions(), round > 0, RoundProgress(progress, round),
                    &report)) {
      return report;
    }
    progress.ThrowIfCancelled();
    if (round == 0) min_kept = (report.num_pairs_used + 1) / 2;
    const bool may_reject = round < options.sync_test.max_rounds;
    if (!TestSynchronisation(used, options, may_reject, min_kept, &report)) break;
    report.sync_rounds = round + 1;
  }
  SetRigUncertainty(used, options, &report);
  report.success = true;
  progress.Report(1.0, "done", RelativePoseSummary(report));
  return report;
}

}  // namespace omnirig
