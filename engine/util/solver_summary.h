#pragma once
// What every non-linear least-squares solve of the engine reports (calibration, relative pose,
// bundle adjustment, pose graph): one struct, embedded in each report, filled from Ceres'
// summary by Summarize (engine/geometry/ceres_problem.h).

#include <string>

namespace omnirig {

struct SolverSummary {
  // Ceres' iterations (summary.iterations.size(): iteration 0, the initial evaluation,
  // included); a solve in rounds says how it sums them.
  int num_iterations = 0;
  double initial_cost = 0.0;  // Ceres' cost: half the sum of squared residuals
  double final_cost = 0.0;
  std::string termination;  // Ceres' termination type: "CONVERGENCE", "NO_CONVERGENCE", ...
  double time_s = 0.0;      // wall clock of the solve(s)
  bool usable = false;      // the solver ended with a usable solution
};

}  // namespace omnirig
