#include "engine/calib/calibrate.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include <ceres/ceres.h>

#include "engine/calib/initialize.h"
#include "engine/geometry/ceres_problem.h"
#include "engine/geometry/reprojection_cost.h"
#include "engine/util/option_check.h"
#include "engine/util/timer.h"

namespace omnirig {
namespace {

using I = UnifiedIntrinsics;

// Residual blocks (corners) per solver thread; see Solve().
constexpr int kResidualBlocksPerThread = 10000;

// One view during the solve: its corners, which of them are inliers, and its pose block.
struct ViewState {
  int input_index = 0;
  std::vector<Eigen::Vector3d> object_points;
  std::vector<Eigen::Vector2d> corners_px;
  std::vector<int> corner_ids;
  std::vector<bool> inlier;
  std::array<double, 7> cam_from_board{};
};

std::string FormatPx(double value) {
  std::ostringstream os;
  os.precision(3);
  os << value << " px";
  return os.str();
}

int CountInliers(const ViewState& view) {
  return static_cast<int>(std::count(view.inlier.begin(), view.inlier.end(), true));
}

// A corner's reprojection error vector, or nullopt when it does not project.
std::optional<Eigen::Vector2d> CornerError(const UnifiedIntrinsics& intrinsics,
                                           const ViewState& view, int i) {
  const Rigid3d cam_from_board = Rigid3d::FromParams(view.cam_from_board.data());
  const auto pixel = Project(intrinsics, cam_from_board * view.object_points[i]);
  if (!pixel) return std::nullopt;
  return Eigen::Vector2d(*pixel - view.corners_px[i]);
}

double ViewInlierRms(const UnifiedIntrinsics& intrinsics, const ViewState& view) {
  double sum2 = 0.0;
  int n = 0;
  for (size_t i = 0; i < view.corners_px.size(); ++i) {
    if (!view.inlier[i]) continue;
    const auto error = CornerError(intrinsics, view, static_cast<int>(i));
    if (!error) return std::numeric_limits<double>::infinity();
    sum2 += error->squaredNorm();
    ++n;
  }
  return n > 0 ? std::sqrt(sum2 / n) : std::numeric_limits<double>::infinity();
}

// Checkerboard detections may come with a mirrored corner numbering (a labelling that no rigid
// board pose explains). The image orientation of the grid at corner 0 is the same in every view
// of one camera, so views against the majority get their rows renumbered.
void HarmoniseOrderings(const BoardSpec& board, std::vector<ViewState>* views) {
  if (board.type != BoardSpec::Type::kCheckerboard) return;
  auto orientation = [&](const ViewState& view) -> int {
    const auto find = [&](int id) -> const Eigen::Vector2d* {
      for (size_t i = 0; i < view.corner_ids.size(); ++i) {
        if (view.corner_ids[i] == id) return &view.corners_px[i];
      }
      return nullptr;
    };
    const Eigen::Vector2d* origin = find(0);
    const Eigen::Vector2d* along_row = find(1);
    const Eigen::Vector2d* along_col = find(board.cols);
    if (!origin || !along_row || !along_col) return 0;
    const Eigen::Vector2d a = *along_row - *origin;
    const Eigen::Vector2d b = *along_col - *origin;
    const double cross = a.x() * b.y() - a.y() * b.x();
    return cross > 0 ? 1 : (cross < 0 ? -1 : 0);
  };
  int balance = 0;
  for (const ViewState& view : *views) balance += orientation(view);
  if (balance == 0) return;
  const int majority = balance > 0 ? 1 : -1;
  const std::vector<Eigen::Vector3d> object_points = board.ObjectPoints();
  for (ViewState& view : *views) {
    if (orientation(view) != -majority) continue;
    for (size_t i = 0; i < view.corner_ids.size(); ++i) {
      const int row = view.corner_ids[i] / board.cols;
      const int col = view.corner_ids[i] % board.cols;
      view.corner_ids[i] = (board.rows - 1 - row) * board.cols + col;
      view.object_points[i] = object_points[view.corner_ids[i]];
    }
  }
}

// Turns detections into view states; unusable ones are marked in `images` with the reason.
std::vector<ViewState> CollectViews(const std::vector<CalibrationView>& views,
                                    const BoardSpec& board, const CalibrationOptions& options,
                                    std::vector<CalibrationImageReport>* images) {
  const std::vector<Eigen::Vector3d> object_points = board.ObjectPoints();
  std::vector<ViewState> states;
  for (size_t v = 0; v < views.size(); ++v) {
    const BoardDetection& detection = views[v].detection;
    CalibrationImageReport& image = (*images)[v];
    image.name = views[v].name;
    image.detector = detection.method;
    image.corners_px = detection.corners_px;
    image.corner_ids = detection.corner_ids;
    if (!detection.found) {
      image.reason = detection.reason.empty() ? "board not found" : detection.reason;
      continue;
    }
    OMNIRIG_CHECK(detection.corners_px.size() == detection.corner_ids.size(),
                  "calibration: view '" << views[v].name << "' has " << detection.corners_px.size()
                                        << " corners but " << detection.corner_ids.size()
                                        << " ids");
    if (static_cast<int>(detection.corners_px.size()) < options.min_corners_per_view) {
      image.reason = "only " + std::to_string(detection.corners_px.size()) + " corners";
      continue;
    }
    ViewState state;
    state.input_index = static_cast<int>(v);
    state.corners_px = detection.corners_px;
    state.corner_ids = detection.corner_ids;
    for (int id : detection.corner_ids) {
      OMNIRIG_CHECK(id >= 0 && id < board.NumCorners(), "calibration: view '"
                                                            << views[v].name << "' has corner id "
                                                            << id << " outside the board");
      state.object_points.push_back(object_points[id]);
    }
    state.inlier.assign(state.corners_px.size(), true);
    states.push_back(std::move(state));
  }
  HarmoniseOrderings(board, &states);
  return states;
}

std::vector<std::vector<int>> BoardLines(const BoardSpec& board, const std::vector<int>& ids) {
  std::vector<std::vector<int>> rows(board.rows), cols(board.cols);
  for (size_t i = 0; i < ids.size(); ++i) {
    rows[ids[i] / board.cols].push_back(static_cast<int>(i));
    cols[ids[i] % board.cols].push_back(static_cast<int>(i));
  }
  std::vector<std::vector<int>> lines;
  for (auto* group : {&rows, &cols}) {
    for (auto& line : *group) {
      if (line.size() >= 3) lines.push_back(std::move(line));
    }
  }
  return lines;
}

[[noreturn]] void ThrowTooFewViews(const std::vector<CalibrationImageReport>& images,
                                   int num_usable, const CalibrationOptions& options) {
  std::ostringstream os;
  os << "calibration needs at least " << options.min_views << " usable views, got " << num_usable
     << ":";
  for (const auto& image : images) {
    os << "\n  " << image.name << ": " << (image.reason.empty() ? "usable" : image.reason);
  }
  throw InvalidArgument(os.str());
}

// Closed-form initial model and poses; views whose pose fails are marked unused.
UnifiedIntrinsics Initialise(const BoardSpec& board, const CalibrationOptions& options, int width,
                             int height, std::vector<ViewState>* views,
                             std::vector<CalibrationImageReport>* images) {
  std::vector<InitView> init_views;
  for (const ViewState& view : *views) {
    init_views.push_back({view.object_points, view.corners_px, BoardLines(board, view.corner_ids)});
  }
  std::vector<Eigen::Vector2d> principal_points;
  if (options.principal_point_px) principal_points.push_back(*options.principal_point_px);
  if (options.rim_circle_px) principal_points.push_back(options.rim_circle_px->head<2>());
  if (principal_points.empty()) {
    principal_points.emplace_back((width - 1) / 2.0, (height - 1) / 2.0);
  }
  const std::optional<InitResult> init =
      InitializeUnified(init_views, width, height, principal_points);
  if (!init) {
    for (const ViewState& view : *views) {
      (*images)[view.input_index].reason = "no initial model explains the corners";
    }
    views->clear();
    return UnifiedIntrinsics();
  }
  std::vector<ViewState> kept;
  for (size_t v = 0; v < views->size(); ++v) {
    if (!init->cam_from_board[v]) {
      (*images)[(*views)[v].input_index].reason = "no initial board pose";
      continue;
    }
    (*views)[v].cam_from_board = init->cam_from_board[v]->ToParams();
    kept.push_back(std::move((*views)[v]));
  }
  *views = std::move(kept);
  return init->camera.intrinsics;
}

// Builds eq. (7) over the inlier corners and solves it.
ceres::Solver::Summary Solve(const CalibrationOptions& options, bool robust, int round,
                             const ProgressSink& progress, UnifiedIntrinsics* intrinsics,
                             std::vector<ViewState>* views, ceres::Problem* problem) {
  for (ViewState& view : *views) {
    for (size_t i = 0; i < view.corners_px.size(); ++i) {
      if (!view.inlier[i]) continue;
      ceres::LossFunction* loss = robust && options.huber_loss_px > 0
                                      ? new ceres::HuberLoss(options.huber_loss_px)
                                      : nullptr;
      problem->AddResidualBlock(
          ReprojectionCost::BoardCorner(view.object_points[i], view.corners_px[i]), loss,
          view.cam_from_board.data(), intrinsics->params.data());
    }
    problem->SetManifold(view.cam_from_board.data(), NewPoseManifold());
  }
  std::vector<int> fixed;
  for (int i = 0; i < I::kNumParams; ++i) {
    if (options.fixed[i]) fixed.push_back(i);
  }
  if (static_cast<int>(fixed.size()) == I::kNumParams) {
    problem->SetParameterBlockConstant(intrinsics->params.data());
  } else if (!fixed.empty()) {
    problem->SetManifold(intrinsics->params.data(),
                         new ceres::SubsetManifold(I::kNumParams, fixed));
  }
  // With analytic Jacobians an iteration over a few thousand corners takes a fraction of a
  // millisecond, less than handing work to a second thread costs (measured: 2 threads slower
  // than 1 on every real set); threads pay off only on much larger problems.
  const int num_threads =
      std::min(options.num_threads, 1 + problem->NumResidualBlocks() / kResidualBlocksPerThread);
  // Tolerances tight enough to reach the minimum on every set, without tuning per set.
  ceres::Solver::Options solver_options = MakeSolverOptions(
      SolverSetup(static_cast<int>(views->size()) + 1, options.max_num_iterations, num_threads)
          .Tolerances(1e-10, 1e-10, 1e-10));
  // xi, gamma and k1 trade off along a narrow curved valley (xi is weakly observable): strictly
  // monotone LM crawls along it in tiny steps (42 iterations on ocamcalib-vmr), non-monotone
  // steps take 13 to the same minimum. Ceres returns the parameters of the lowest cost seen.
  solver_options.use_nonmonotonic_steps = true;
  // Four rounds of the robust solve fill the fraction from 0.1 to 0.9.
  const auto fraction_at = [&](int iteration) {
    const double within =
        std::min(1.0, iteration / static_cast<double>(options.max_num_iterations));
    return 0.1 + 0.8 * std::min(1.0, (round + within) / 4.0);
  };
  SolverProgress callback(progress, "solve", fraction_at,
                          "round " + std::to_string(round + 1) + ", ");
  solver_options.callbacks.push_back(&callback);
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, problem, &summary);
  progress.ThrowIfCancelled();
  return summary;
}

// Marks corners beyond the robust threshold as outliers and drops views that stay bad.
// Returns true when anything changed.
bool RejectOutliers(const UnifiedIntrinsics& intrinsics, const CalibrationOptions& options,
                    std::vector<ViewState>* views, std::vector<CalibrationImageReport>* images,
                    CalibrationSolverSummary* solver) {
  std::vector<double> errors;
  for (const ViewState& view : *views) {
    for (size_t i = 0; i < view.corners_px.size(); ++i) {
      const auto error = CornerError(intrinsics, view, static_cast<int>(i));
      if (view.inlier[i] && error) errors.push_back(error->norm());
    }
  }
  if (errors.empty()) return false;
  std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
  // For isotropic Gaussian noise of std sigma per axis the median of |e| is 1.1774 sigma.
  const double sigma = errors[errors.size() / 2] / 1.1774;
  const double threshold = std::max(options.outlier_sigmas * sigma, options.min_outlier_px);
  bool changed = false;
  std::vector<ViewState> kept;
  for (ViewState& view : *views) {
    for (size_t i = 0; i < view.corners_px.size(); ++i) {
      const auto error = CornerError(intrinsics, view, static_cast<int>(i));
      if (view.inlier[i] && (!error || error->norm() > threshold)) {
        view.inlier[i] = false;
        ++solver->num_rejected_corners;
        changed = true;
      }
    }
    const double rms = ViewInlierRms(intrinsics, view);
    CalibrationImageReport& image = (*images)[view.input_index];
    if (CountInliers(view) < options.min_corners_per_view) {
      image.reason = "too few inlier corners after outlier rejection";
    } else if (!(rms <= options.max_view_rms_px)) {
      image.reason = "view RMS " + FormatPx(rms) + " exceeds max_view_rms_px";
    } else {
      kept.push_back(std::move(view));
      continue;
    }
    ++solver->num_rejected_views;
    changed = true;
  }
  *views = std::move(kept);
  return changed;
}

// Standard deviations of the intrinsics from the covariance of the last problem, scaled by the
// residual variance. Zeros when the covariance is rank deficient.
std::array<double, I::kNumParams> IntrinsicsStd(ceres::Problem* problem,
                                                UnifiedIntrinsics* intrinsics, double cost,
                                                int num_residuals, int num_free_parameters) {
  std::array<double, I::kNumParams> stds{};
  const int dof = num_residuals - num_free_parameters;
  if (dof <= 0 || problem->IsParameterBlockConstant(intrinsics->params.data())) return stds;
  ceres::Covariance::Options covariance_options;
  // SPARSE_QR: DENSE_SVD would run Ceres' own instantiation of Eigen's SVD next to ours (one
  // definition, two allocation settings: AddressSanitizer reports a bad free).
  covariance_options.algorithm_type = ceres::SPARSE_QR;
  ceres::Covariance covariance(covariance_options);
  const double* block = intrinsics->params.data();
  const std::vector<std::pair<const double*, const double*>> blocks = {{block, block}};
  if (!covariance.Compute(blocks, problem)) return stds;
  Eigen::Matrix<double, I::kNumParams, I::kNumParams, Eigen::RowMajor> matrix;
  covariance.GetCovarianceBlock(block, block, matrix.data());
  const double variance = 2.0 * cost / dof;
  for (int i = 0; i < I::kNumParams; ++i)
    stds[i] = std::sqrt(std::max(0.0, matrix(i, i) * variance));
  return stds;
}

// Fills per-image and overall errors from the final model.
void Evaluate(const std::vector<ViewState>& views, CalibrationReport* report) {
  const UnifiedIntrinsics& intrinsics = report->camera.intrinsics;
  std::vector<double> inlier_errors;
  double sum2_all = 0.0;
  int num_all = 0;
  for (const ViewState& view : views) {
    CalibrationImageReport& image = report->images[view.input_index];
    image.used = true;
    image.reason.clear();
    image.cam_from_board = Rigid3d::FromParams(view.cam_from_board.data());
    image.corners_px = view.corners_px;
    image.corner_ids = view.corner_ids;
    image.inlier = view.inlier;
    image.rms_px = ViewInlierRms(intrinsics, view);
    image.reprojected_px.clear();
    for (size_t i = 0; i < view.corners_px.size(); ++i) {
      const auto error = CornerError(intrinsics, view, static_cast<int>(i));
      const Eigen::Vector2d e = error ? *error : Eigen::Vector2d::Constant(1e6);
      image.reprojected_px.push_back(view.corners_px[i] + e);
      sum2_all += e.squaredNorm();
      ++num_all;
      if (view.inlier[i]) inlier_errors.push_back(e.norm());
    }
  }
  double sum = 0.0, sum2 = 0.0;
  for (double e : inlier_errors) {
    sum += e;
    sum2 += e * e;
  }
  const double n = std::max<double>(1.0, inlier_errors.size());
  report->rms_px = std::sqrt(sum2 / n);
  report->mean_px = sum / n;
  report->std_px = std::sqrt(std::max(0.0, sum2 / n - report->mean_px * report->mean_px));
  report->rms_all_px = std::sqrt(sum2_all / std::max(1, num_all));
  report->num_views_used = static_cast<int>(views.size());
}

// Ceres' BriefReport() describes one solve; the calibration runs several (robust rounds, then a
// plain one), so its line is written from the totals in the shape Ceres uses.
std::string SolverBrief(const CalibrationSolverSummary& solver) {
  std::ostringstream os;
  os << "Ceres Solver Report: Iterations: " << solver.num_iterations << " over "
     << solver.num_rounds << (solver.num_rounds == 1 ? " solve" : " solves")
     << ", Initial cost: " << std::scientific << solver.initial_cost
     << ", Final cost: " << solver.final_cost << ", Termination: " << solver.termination;
  return os.str();
}

}  // namespace

void CalibrationOptions::SetFixed(const std::string& name, bool fix) {
  if (name == "skew") {
    fixed[I::kAlpha] = fix;
  } else if (name == "tangential") {
    fixed[I::kK3] = fixed[I::kK4] = fix;
  } else if (name == "principal_point") {
    fixed[I::kU0] = fixed[I::kV0] = fix;
  } else if (name == "gamma") {
    fixed[I::kGammaU] = fixed[I::kGammaV] = fix;
  } else {
    for (int i = 0; i < I::kNumParams; ++i) {
      if (name == I::kNames[i]) {
        fixed[i] = fix;
        return;
      }
    }
    OMNIRIG_CHECK(false, "calibration: unknown parameter '"
                             << name
                             << "' (expected xi, gamma_u, gamma_v, u0, v0, alpha, k1..k5, skew, "
                                "tangential, principal_point, gamma)");
  }
}

void CalibrationOptions::Check() const {
  OMNIRIG_CHECK_NON_NEGATIVE(huber_loss_px);
  OMNIRIG_CHECK_POSITIVE(outlier_sigmas);
  OMNIRIG_CHECK_NON_NEGATIVE(min_outlier_px);
  OMNIRIG_CHECK_IN(max_rejection_rounds, '[', 0, 20, ']');
  OMNIRIG_CHECK_POSITIVE(max_view_rms_px);
  OMNIRIG_CHECK_AT_LEAST(min_corners_per_view, 4);
  OMNIRIG_CHECK_AT_LEAST(min_views, 1);
  OMNIRIG_CHECK_IN(max_num_iterations, '[', 1, 10000, ']');
  OMNIRIG_CHECK_IN(num_threads, '[', 1, 256, ']');
  if (principal_point_px) {
    OMNIRIG_CHECK(principal_point_px->allFinite(), "calibration: principal point not finite");
  }
  if (rim_circle_px) {
    OMNIRIG_CHECK(rim_circle_px->allFinite() && rim_circle_px->z() > 0,
                  "calibration: rim circle must be finite with a positive radius");
  }
}

CalibrationReport Calibrate(const std::vector<CalibrationView>& views, int width, int height,
                            const BoardSpec& board, const CalibrationOptions& options,
                            const ProgressSink& progress) {
  board.Check();
  options.Check();
  OMNIRIG_CHECK(width > 0 && height > 0 && width <= 100000 && height <= 100000,
                "calibration: invalid image size " << width << " x " << height);
  Timer total_timer;
  CalibrationReport report;
  report.camera.width = width;
  report.camera.height = height;
  report.images.resize(views.size());
  std::vector<ViewState> states = CollectViews(views, board, options, &report.images);
  if (static_cast<int>(states.size()) < options.min_views) {
    ThrowTooFewViews(report.images, static_cast<int>(states.size()), options);
  }
  progress.Report(0.0, "init", "closed-form initialisation");
  Timer timer;
  UnifiedIntrinsics intrinsics = Initialise(board, options, width, height, &states, &report.images);
  report.timings.init_s = timer.ElapsedSeconds();
  if (static_cast<int>(states.size()) < options.min_views) {
    ThrowTooFewViews(report.images, static_cast<int>(states.size()), options);
  }
  timer.Restart();
  ceres::Solver::Summary summary;
  auto problem = std::make_unique<ceres::Problem>();
  // Robust rounds, each followed by outlier rejection, then one plain least-squares solve over
  // the inliers (the maximum-likelihood estimate, whose covariance the report gives).
  for (int round = 0;; ++round) {
    problem = std::make_unique<ceres::Problem>();
    const bool robust = round < options.max_rejection_rounds;
    summary = Solve(options, robust, round, progress, &intrinsics, &states, problem.get());
    if (round == 0) report.solver.initial_cost = summary.initial_cost;
    report.solver.num_iterations += static_cast<int>(summary.iterations.size()) - 1;
    report.solver.num_rounds = round + 1;
    if (!robust) break;
    if (!RejectOutliers(intrinsics, options, &states, &report.images, &report.solver)) {
      round = options.max_rejection_rounds - 1;  // nothing rejected: the plain solve is next
    }
    if (static_cast<int>(states.size()) < options.min_views) {
      ThrowTooFewViews(report.images, static_cast<int>(states.size()), options);
    }
  }
  report.timings.solve_s = timer.ElapsedSeconds();
  report.solver.final_cost = summary.final_cost;
  report.solver.termination = ceres::TerminationTypeToString(summary.termination_type);
  report.solver.time_s = report.timings.solve_s;
  report.solver.usable = summary.IsSolutionUsable();
  report.solver.num_residuals = summary.num_residuals;
  report.solver.num_parameters = summary.num_effective_parameters;
  report.solver.brief = SolverBrief(report.solver);
  timer.Restart();
  report.intrinsics_std = IntrinsicsStd(problem.get(), &intrinsics, summary.final_cost,
                                        summary.num_residuals, summary.num_effective_parameters);
  report.timings.covariance_s = timer.ElapsedSeconds();
  report.camera.intrinsics = intrinsics;
  Evaluate(states, &report);
  report.timings.total_s = total_timer.ElapsedSeconds();
  progress.Report(1.0, "done", "RMS " + FormatPx(report.rms_px));
  return report;
}

}  // namespace omnirig
