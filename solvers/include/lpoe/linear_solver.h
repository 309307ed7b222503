// The paper's linearized iterative least squares (Fig. 5).
//
// Each iteration linearizes the error model around the current local frames,
//   position data (eqs. (29)-(31)):  y = P_measured - P_model = J x,  J = [-P^ I3] [Ad_G_1 ... Ad_G_n+1]
//   pose data (eqs. (18)-(22)):      y = log(T_measured T_model^-1)^vee = A x,  A = [Ad_G_1 ...]
// solves for x in least squares, and updates T_f <- T_f exp((B_f x_f)^) (eq. (19)), until ||x|| < eps.
//
// x lives in the chosen parameterization: `identifiable` (per frame only the directions data can see,
// docs/conventions.md; J^T J is then full rank on exciting data) or `full` (6 per frame, the paper's
// 42 for cobot6; J^T J is singular and the step is the minimum-norm pseudo-inverse solution).
//
// The columns of J are scaled to unit norm before solving (rotation columns carry lever arms of ~1 m,
// translation columns ~1), and the rank and condition number of the scaled J decide whether the data
// can identify the parameters at all: data that cannot is refused, never "solved".
#ifndef LPOE_LINEAR_SOLVER_H_
#define LPOE_LINEAR_SOLVER_H_

#include <functional>
#include <memory>
#include <vector>

#include "lpoe/calibration.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/convergence.h"
#include "lpoe/model/prior.h"
#include "lpoe/problem_options.h"
#include "lpoe/model/statistics.h"

namespace lpoe {

// What the solver's passes over the rows leave for the caller's analysis, so that the statistics and
// the outlier search need no forward-kinematics pass of their own (docs/performance.md). Filled for
// position data without joint-space terms; otherwise left as it is.
struct LinearSolverErrors {
  // In: also keep the statistics of the errors at the model the solve starts from (those of its
  // first linearization).
  bool want_start_statistics = false;
  // Out: those statistics (as PositionErrorStatistics, to round-off).
  bool have_start_statistics = false;
  ErrorStatistics start_statistics;
  // Out: the errors of the last linearization when it is that of the returned model (converged,
  // or at the iteration limit); empty otherwise. 16 bytes a row.
  PositionErrorRows final_errors;
};

// The problem's decisions (parameterization, use_orientation, orientation_weight,
// structure_reference, joint_terms, joint_term_tolerance, gravity_tilt, initial_joint_terms, prior)
// are the base's (problem_options.h); the fields below are how to solve.
struct LinearSolverOptions : ProblemDefinitionOptions {
  int max_iterations = 30;
  // Stop when ||x|| < step_tolerance (x mixes rad and mm; both are small near convergence), or on
  // one of the rules of convergence.h that fit large-residual data (convergence.step_tolerance is
  // not used: this field is).
  double step_tolerance = 1e-10;
  ConvergenceOptions convergence;
  // Refuse the data when the condition number of the column-scaled Jacobian exceeds this: the
  // parameters are then not determined by the data (degenerate or too few poses).
  double max_condition_number = 1e8;
  // Relative singular-value threshold of the pseudo-inverse (full parameterization).
  double pseudo_inverse_tolerance = 1e-9;
  // Print one line per iteration to stderr (LOG(INFO)).
  bool verbose = false;
  // Solve only these directions instead of `parameterization` (e.g. the base and tool frames during
  // registration, see registration.h). Not owned; must outlive the call.
  const Parameterization* parameterization_override = nullptr;
  // Estimate the covariance of the identified parameters at the solution:
  // s^2 (J^T J)^-1 with the a-posteriori variance factor s^2 = |y|^2 / (rows - parameters).
  bool compute_covariance = true;
  // Called after every iteration (e.g. for a progress line).
  std::function<void(const IterationRecord&)> on_iteration;
  // When not null: filled as described there. Not owned.
  LinearSolverErrors* errors = nullptr;
  // Warm start on large data (docs/performance.md): with at least `warm_start_min_rows` rows (and
  // twice `warm_start_rows`), in the identifiable parameterization of the frames only (no override,
  // no joint-space terms, no gravity tilt), the first step is computed on all rows as always, and
  // the iterations after it run on every k-th row (about `warm_start_rows` of them, in order) until
  // they converge there; the solve then continues on all rows from that point, where convergence
  // is tested as always. The start model's statistics, the identifiability check, and the
  // solution's normal equations and covariance are those of all rows; the subsample's iterations
  // are in the history with their row count (IterationRecord::rows). The solution is that of the
  // solve without it to within the convergence tolerance. warm_start_rows = 0: never.
  int warm_start_min_rows = 100000;
  int warm_start_rows = 20000;
};

CalibrationResult CalibrateLinear(const RobotModel& nominal, const MeasurementSet& data,
                                  const LinearSolverOptions& options = LinearSolverOptions());

}  // namespace lpoe

#endif  // LPOE_LINEAR_SOLVER_H_
