#include "engine/rig/relpose_model_select.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "engine/estimators/board_pose.h"
#include "engine/rig/relpose_corner_order.h"
#include "engine/rig/relpose_refine.h"
#include "engine/util/parallel.h"

namespace omnirig {

int RigIntrinsicsModel::NumFreeIntrinsics() const {
  if (!refine_intrinsics) return 0;
  int count = 0;
  for (int camera = 0; camera < 2; ++camera) {
    for (bool fixed : JointFixed(camera)) count += fixed ? 0 : 1;
  }
  return count;
}

namespace {

// `base` with the tangential terms k3, k4 fixed too.
RigIntrinsicsModel::FixedSet WithoutTangential(const RigIntrinsicsModel::FixedSet& base) {
  RigIntrinsicsModel::FixedSet fixed = base;
  fixed[UnifiedIntrinsics::kK3] = true;
  fixed[UnifiedIntrinsics::kK4] = true;
  return fixed;
}

}  // namespace

std::vector<RigIntrinsicsModel> StandardRigIntrinsicsModels(
    const std::array<bool, UnifiedIntrinsics::kNumParams>& base) {
  const RigIntrinsicsModel::FixedSet no_tangential = WithoutTangential(base);
  return {{"fixed", base, false, base, std::nullopt, std::nullopt},
          {"tangential_fixed", no_tangential, true, no_tangential, std::nullopt, std::nullopt},
          {"free", base, true, base, std::nullopt, std::nullopt}};
}

std::vector<RigIntrinsicsModel> PerCameraTangentialModels(
    const std::array<bool, UnifiedIntrinsics::kNumParams>& base) {
  const RigIntrinsicsModel::FixedSet no_tangential = WithoutTangential(base);
  std::vector<RigIntrinsicsModel> models(2);
  for (int camera = 0; camera < 2; ++camera) {
    RigIntrinsicsModel& model = models[camera];
    model.name = "tangential_free_cam" + std::to_string(camera);
    model.refine_intrinsics = true;
    model.calibration_fixed = model.joint_fixed = camera == 0 ? base : no_tangential;
    model.cam1_calibration_fixed = model.cam1_joint_fixed = camera == 1 ? base : no_tangential;
  }
  return models;
}

std::vector<RigIntrinsicsModel> AutoRigIntrinsicsModels(
    const std::array<bool, UnifiedIntrinsics::kNumParams>& base) {
  std::vector<RigIntrinsicsModel> models = StandardRigIntrinsicsModels(base);
  if (models[1].joint_fixed == models[2].joint_fixed) {
    models.erase(models.begin() + 1);  // "tangential_fixed" is "free" when base fixes k3, k4
    return models;
  }
  for (const RigIntrinsicsModel& model : PerCameraTangentialModels(base)) {
    models.insert(models.end() - 1, model);
  }
  return models;
}

namespace {

// Pair i's corners with cam1's ids relabelled by its chosen corner order.
RigPairCorners CornersOf(const BoardSpec& board, const std::vector<BoardSymmetry>& symmetries,
                         const StereoBoardPair& pair, int cam1_order) {
  const std::vector<Eigen::Vector3d> object = board.ObjectPoints();
  RigPairCorners corners;
  for (size_t c = 0; c < pair.cam0.corner_ids.size(); ++c) {
    corners.points_in_board0.push_back(object[pair.cam0.corner_ids[c]]);
    corners.pixels0.push_back(pair.cam0.corners_px[c]);
  }
  const std::vector<int>& permutation = symmetries[cam1_order].permutation;
  for (size_t c = 0; c < pair.cam1.corner_ids.size(); ++c) {
    corners.points_in_board1.push_back(object[permutation[pair.cam1.corner_ids[c]]]);
    corners.pixels1.push_back(pair.cam1.corners_px[c]);
  }
  return corners;
}

// Squared pixel errors of `pixels` projected from `cam_from_board`; a corner that does not
// project counts 1e6 px^2, as in PairRmsPx.
double SumSquaredErrors(const CameraModel& camera, const Rigid3d& cam_from_board,
                        const std::vector<Eigen::Vector3d>& points,
                        const std::vector<Eigen::Vector2d>& pixels) {
  double sum = 0.0;
  for (size_t c = 0; c < pixels.size(); ++c) {
    const auto projected = Project(camera.intrinsics, cam_from_board * points[c]);
    sum += projected ? (*projected - pixels[c]).squaredNorm() : 1e6;
  }
  return sum;
}

// The held-out pair predicted by `rig`: the board's pose from one camera's corners alone, the
// other camera's corners through the rig, both ways round. Sum of squares and corner count.
std::pair<double, int> PredictionError(const StereoRig& rig, const RigPairCorners& pair) {
  const double unpredictable = 1e6 * (pair.pixels0.size() + pair.pixels1.size());
  const int count = static_cast<int>(pair.pixels0.size() + pair.pixels1.size());
  const auto cam0_from_board = EstimateBoardPose(rig.cam0, pair.points_in_board0, pair.pixels0);
  const auto cam1_from_board = EstimateBoardPose(rig.cam1, pair.points_in_board1, pair.pixels1);
  if (!cam0_from_board || !cam1_from_board) return {unpredictable, count};
  const double sum = SumSquaredErrors(rig.cam1, rig.cam0_from_cam1.Inverse() * *cam0_from_board,
                                      pair.points_in_board1, pair.pixels1) +
                     SumSquaredErrors(rig.cam0, rig.cam0_from_cam1 * *cam1_from_board,
                                      pair.points_in_board0, pair.pixels0);
  return {sum, count};
}

// One fold: the candidate's all-pairs solution refined again without pair `held_out`, then
// that pair predicted. Sum of squares and corner count.
std::pair<double, int> FoldError(const BoardSpec& board,
                                 const std::vector<BoardSymmetry>& symmetries,
                                 const std::vector<StereoBoardPair>& pairs,
                                 const RelativePoseReport& fit, const RigRefinementOptions& refine,
                                 size_t held_out) {
  std::vector<RigPairCorners> corners;
  std::vector<Rigid3d> cam0_from_board;
  for (size_t i = 0; i < pairs.size(); ++i) {
    if (!fit.pairs[i].used || i == held_out) continue;
    corners.push_back(CornersOf(board, symmetries, pairs[i], fit.pairs[i].cam1_order));
    cam0_from_board.push_back(fit.pairs[i].cam0_from_board);
  }
  StereoRig rig = fit.rig;
  const SolverSummary summary = RefineRig(corners, refine, &rig, &cam0_from_board, nullptr);
  const RigPairCorners test =
      CornersOf(board, symmetries, pairs[held_out], fit.pairs[held_out].cam1_order);
  if (!summary.usable) {
    return {1e6 * (test.pixels0.size() + test.pixels1.size()),
            static_cast<int>(test.pixels0.size() + test.pixels1.size())};
  }
  return PredictionError(rig, test);
}

// The one-standard-error rule over the scored candidates (cv_rms_px >= 0), given each one's
// per-fold sums of squares. Fills the excess columns, `chosen`, `lowest_error` and `rule`.
void ApplyOneStandardErrorRule(const std::vector<std::vector<double>>& fold_sums,
                               double total_count, RigModelSelection* selection) {
  auto& scores = selection->candidates;
  for (size_t k = 0; k < scores.size(); ++k) {
    if (scores[k].cv_rms_px < 0.0) continue;
    if (selection->lowest_error < 0 ||
        scores[k].cv_rms_px < scores[selection->lowest_error].cv_rms_px) {
      selection->lowest_error = static_cast<int>(k);
    }
  }
  if (selection->lowest_error < 0) return;
  const std::vector<double>& best = fold_sums[selection->lowest_error];
  const double num_folds = static_cast<double>(best.size());
  for (size_t k = 0; k < scores.size(); ++k) {
    if (scores[k].cv_rms_px < 0.0) continue;
    double mean = 0.0, var = 0.0;
    for (size_t f = 0; f < best.size(); ++f) mean += (fold_sums[k][f] - best[f]) / num_folds;
    for (size_t f = 0; f < best.size(); ++f) {
      var += std::pow(fold_sums[k][f] - best[f] - mean, 2) / std::max(1.0, num_folds - 1.0);
    }
    // Per corner: the excess of the pooled mean square, and its standard error.
    scores[k].cv_excess_mse_px2 = mean * num_folds / total_count;
    scores[k].cv_excess_se_px2 = std::sqrt(var / num_folds) * num_folds / total_count;
  }
  std::vector<size_t> order;
  for (size_t k = 0; k < scores.size(); ++k) {
    if (scores[k].cv_rms_px >= 0.0) order.push_back(k);
  }
  std::stable_sort(order.begin(), order.end(), [&scores](size_t a, size_t b) {
    return scores[a].num_free_intrinsics < scores[b].num_free_intrinsics;
  });
  for (size_t k : order) {
    if (scores[k].cv_excess_mse_px2 <= scores[k].cv_excess_se_px2) {
      selection->chosen = static_cast<int>(k);
      break;
    }
  }
  std::ostringstream os;
  os << "leave-one-pair-out prediction over " << selection->held_out.size()
     << " pairs; lowest error: " << scores[selection->lowest_error].name << " ("
     << scores[selection->lowest_error].cv_rms_px << " px); chosen: the simplest model within "
     << "one standard error of it: " << scores[selection->chosen].name;
  selection->rule = os.str();
}

// Every candidate fitted on all pairs; `candidate_options` receives the options of each. The
// job's threads run candidates side by side, one solver thread each (a rig problem of a few
// dozen pairs keeps one thread busy better than several).
void FitCandidates(const BoardSpec& board, const std::vector<StereoBoardPair>& pairs,
                   const std::vector<RigModelCandidate>& candidates,
                   const RelativePoseOptions& options, const ProgressSink& progress,
                   std::vector<RelativePoseOptions>* candidate_options,
                   RigModelSelection* selection) {
  const int num_candidates = static_cast<int>(candidates.size());
  selection->candidates.resize(candidates.size());
  for (const RigModelCandidate& model_candidate : candidates) {
    RelativePoseOptions candidate = options;
    candidate.refine_intrinsics = model_candidate.model.refine_intrinsics;
    candidate.fixed_intrinsics = model_candidate.model.joint_fixed;
    candidate.cam1_fixed_intrinsics = model_candidate.model.cam1_joint_fixed;
    candidate.num_threads = 1;
    candidate_options->push_back(candidate);
  }
  int num_done = 0;
  RunTasks(
      num_candidates, options.num_threads, progress,
      [&](int k, const ProgressSink& cancellation) {
        RigModelScore& score = selection->candidates[k];
        score.name = candidates[k].model.name;
        score.num_free_intrinsics = candidates[k].model.NumFreeIntrinsics();
        score.fit = EstimateRelativePose(candidates[k].cam0, candidates[k].cam1, board, pairs,
                                         (*candidate_options)[k], cancellation);
      },
      [&](int k) {
        progress.Report(0.2 * ++num_done / num_candidates, "model_fit", candidates[k].model.name);
      });
}

// The folds: every pair (not a single camera's view) that all fitted candidates used.
std::vector<size_t> CommonPairs(const RigModelSelection& selection,
                                const std::vector<StereoBoardPair>& pairs) {
  std::vector<size_t> held_out;
  for (size_t i = 0; i < pairs.size(); ++i) {
    bool all = !pairs[i].single_camera_view;
    for (const RigModelScore& score : selection.candidates) {
      if (score.fit.success && !score.fit.pairs[i].used) all = false;
    }
    if (all) held_out.push_back(i);
  }
  return held_out;
}

// Every (candidate, fold) as one task: the held-out pair's sum of squares and corner count
// (FoldError), each fold refitting the candidate as its all-pairs fit was made. Rows of
// candidates that failed, and every row with fewer than 3 folds, stay zero.
std::vector<std::vector<std::pair<double, int>>> CrossValidate(
    const BoardSpec& board, const std::vector<StereoBoardPair>& pairs,
    const std::vector<size_t>& held_out, const std::vector<RelativePoseOptions>& candidate_options,
    const RigModelSelection& selection, int num_threads, const ProgressSink& progress) {
  const size_t num_candidates = candidate_options.size();
  const std::vector<BoardSymmetry> symmetries = BoardGridSymmetries(board);
  std::vector<std::pair<size_t, size_t>> tasks;  // (candidate, fold)
  for (size_t k = 0; k < num_candidates; ++k) {
    if (!selection.candidates[k].fit.success || held_out.size() < 3) continue;
    for (size_t f = 0; f < held_out.size(); ++f) tasks.emplace_back(k, f);
  }
  std::vector<std::vector<std::pair<double, int>>> folds(
      num_candidates, std::vector<std::pair<double, int>>(held_out.size()));
  std::vector<RigRefinementOptions> fold_refine;
  for (const RelativePoseOptions& candidate : candidate_options) {
    fold_refine.push_back(candidate.RefinementOptions());
  }
  int num_done = 0;
  RunTasks(
      static_cast<int>(tasks.size()), num_threads, progress,
      [&](int t, const ProgressSink& cancellation) {
        cancellation.ThrowIfCancelled();
        const auto [k, f] = tasks[t];
        folds[k][f] = FoldError(board, symmetries, pairs, selection.candidates[k].fit,
                                fold_refine[k], held_out[f]);
      },
      [&](int t) {
        const auto [k, f] = tasks[t];
        progress.Report(0.2 + 0.8 * ++num_done / tasks.size(), "cross_validation",
                        selection.candidates[k].name + " without " + pairs[held_out[f]].name);
      });
  return folds;
}

// Each cross-validated candidate's pooled and per-fold held-out RMS from its folds, and its
// per-fold sums of squares (`fold_sums`, for the one-standard-error rule). Returns the number
// of held-out corners (the same for every candidate: the folds hold out the same pairs).
double ScoreFolds(const std::vector<std::vector<std::pair<double, int>>>& folds,
                  bool cross_validated, std::vector<std::vector<double>>* fold_sums,
                  RigModelSelection* selection) {
  fold_sums->assign(folds.size(), {});
  double total_count = 0.0;
  for (size_t k = 0; k < folds.size(); ++k) {
    RigModelScore& score = selection->candidates[k];
    if (!score.fit.success || !cross_validated) continue;
    double sum = 0.0, count = 0.0;
    for (const auto& [fold_sum, fold_count] : folds[k]) {
      (*fold_sums)[k].push_back(fold_sum);
      score.fold_rms_px.push_back(std::sqrt(fold_sum / fold_count));
      sum += fold_sum;
      count += fold_count;
    }
    score.cv_rms_px = std::sqrt(sum / count);
    total_count = count;
  }
  return total_count;
}

}  // namespace

RigModelSelection SelectRigIntrinsicsModel(const BoardSpec& board,
                                           const std::vector<StereoBoardPair>& pairs,
                                           const std::vector<RigModelCandidate>& candidates,
                                           const RelativePoseOptions& options,
                                           const ProgressSink& progress) {
  options.Check();
  RigModelSelection selection;
  std::vector<RelativePoseOptions> candidate_options;
  FitCandidates(board, pairs, candidates, options, progress, &candidate_options, &selection);
  const std::vector<size_t> held_out = CommonPairs(selection, pairs);
  for (size_t i : held_out) selection.held_out.push_back(pairs[i].name);
  const auto folds = CrossValidate(board, pairs, held_out, candidate_options, selection,
                                   options.num_threads, progress);
  std::vector<std::vector<double>> fold_sums;
  const double total_count = ScoreFolds(folds, held_out.size() >= 3, &fold_sums, &selection);
  ApplyOneStandardErrorRule(fold_sums, total_count, &selection);
  if (selection.chosen < 0) {
    // Too few common pairs to cross-validate: the simplest candidate that could be fitted.
    for (size_t k = 0; k < selection.candidates.size() && selection.chosen < 0; ++k) {
      if (selection.candidates[k].fit.success) selection.chosen = static_cast<int>(k);
    }
    selection.rule =
        "fewer than 3 pairs common to every candidate: no cross-validation, the "
        "first candidate that could be fitted";
  }
  return selection;
}

}  // namespace omnirig
