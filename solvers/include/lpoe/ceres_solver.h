// Calibration as a Ceres nonlinear least-squares problem (docs/architecture.md).
//
// One parameter block per local frame (the joints, then the tools that the data measure; tools
// never measured are left out and keep their nominal frames), 7 numbers [qx qy qz qw tx ty tz] with
// an Se3Manifold: right perturbation (eq. (19)) restricted to the frame's basis from
// MakeParameterization. One residual block per measurement:
//   position data:  r = (P_model(q) - P_measured) / sigma                   (position_residual.h)
//   pose data:      r = diag(w,w,w,1,1,1) log(T_measured T_model^-1) / sigma  (pose_residual.h)
// optionally under a robust loss (Huber or Cauchy) for gross errors in the data. Levenberg-Marquardt
// with Jacobi scaling; the same identifiability check as the linear solver refuses data that cannot
// determine the parameters before anything is solved.
//
// With the identifiable parameterization and no robust loss, the solution is the same least-squares
// minimum as CalibrateLinear's: predicted positions agree to ~1e-9 mm. With the full
// parameterization the 15 gauge directions are undetermined; LM's damping picks some point on the
// gauge orbit (not the minimum-norm one of the linear solver's pseudo-inverse): predicted positions
// still agree, the frames themselves differ along the unidentifiable directions.
#ifndef LPOE_CERES_SOLVER_H_
#define LPOE_CERES_SOLVER_H_

#include <algorithm>
#include <functional>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "lpoe/calibration.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/convergence.h"
#include "lpoe/model/prior.h"
#include "lpoe/problem_options.h"
#include "lpoe/status.h"

namespace lpoe {

// The problem's decisions and its cost (parameterization, use_orientation, orientation_weight,
// structure_reference, joint_terms, joint_term_tolerance, gravity_tilt, initial_joint_terms, prior;
// sigma, loss, loss_scale) are the bases' (problem_options.h); the fields below are how to solve.
struct CeresSolverOptions : ProblemCostOptions {
  // Ceres linear solver: auto | dense_qr | dense_normal_cholesky | sparse_normal_cholesky |
  // dense_schur | sparse_schur | iterative_schur | cgnr. The problem is small and dense (every
  // residual touches every joint frame). `auto` (CeresLinearSolverFor) takes
  // dense_normal_cholesky where the normal equations lose nothing that matters (the identifiable
  // parameterization, no robust loss, no gravity tilt, column-scaled condition number at most
  // kNormalEquationsMaxCondition), else dense_qr. With rows in batches (rows_per_block) dense_qr
  // and auto are carried out as dense_normal_cholesky: a QR would copy the Jacobian of every row.
  std::string linear_solver = "auto";
  // kappa^2 eps = 2.2e-8 at this condition number: the relative error of a step solved from the
  // normal equations (docs/joint_errors.md, Cost).
  static constexpr double kNormalEquationsMaxCondition = 1e4;
  int num_threads = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  // Rows per residual block (CalibrationProblemOptions::rows_per_block): 0 picks 1024 from
  // kBatchFromRows rows on (one block per row below, or with a robust loss, pose data or joint
  // terms), where the per-row blocks' overhead dominates; the result is the same either way.
  int rows_per_block = 0;
  static constexpr int kBatchFromRows = 20000;
  int max_iterations = 100;
  // Covariance of the identified parameters at the solution (ceres::Covariance, DENSE_SVD).
  bool compute_covariance = true;
  // Scale the covariance by the a-posteriori variance factor s^2 = 2 cost / (m - p) (cost in
  // whitened units, m residuals, p identifiable parameters), i.e. estimate sigma from the residuals
  // instead of trusting `sigma`. This is what CalibrateLinear reports. Off: the covariance is the
  // a-priori one, exact when `sigma` is the true noise.
  bool a_posteriori_covariance = false;
  // Convergence (ceres::Solver::Options). Tight enough that noise-free data converge to ~1e-9 mm:
  // the LM iterations stop on the parameter tolerance once the cost has reached round-off.
  double function_tolerance = 1e-15;
  double gradient_tolerance = 1e-15;
  double parameter_tolerance = 1e-13;
  // The stopping rules that fit large-residual data (convergence.h), tested after every accepted
  // step on the step just taken (standard deviations from J^T J at the start model and the current
  // cost); the first that holds ends the solve as converged.
  ConvergenceOptions convergence;
  // Refuse data whose column-scaled Jacobian (identifiable basis, nominal model) has a larger
  // condition number, as CalibrateLinear does.
  double max_condition_number = 1e8;
  // Ceres's per-iteration progress on stdout.
  // Called after every accepted iteration (e.g. for a progress line).
  std::function<void(const IterationRecord&)> on_iteration;
  bool verbose = false;
};

// Checks the string options and ranges (user input): linear_solver and loss names, sigma > 0,
// loss_scale > 0, orientation_weight > 0, max_iterations >= 1, num_threads >= 1.
Status ValidateCeresSolverOptions(const CeresSolverOptions& options);

// The Ceres linear solver (its name, as in CeresSolverOptions::linear_solver) that CalibrateCeres
// uses for `options` when the shared identifiability check found the column-scaled condition
// number `condition_number` and the rows are in blocks of `batched_rows`.
std::string CeresLinearSolverFor(const CeresSolverOptions& options, double condition_number,
                                 int batched_rows);

// Calibrates `nominal` on `data` with Ceres. The result has the same meaning as CalibrateLinear's:
//   * termination: ceres CONVERGENCE / USER_SUCCESS -> kConverged, NO_CONVERGENCE ->
//     kMaxIterations, FAILURE / USER_FAILURE -> kNumericalFailure; kNotIdentifiable when the data
//     were refused (too few equations, rank or condition number), with the same message;
//   * history: one record per accepted LM step (iteration 0 = the nominal model), errors and cost of
//     the model *after* that step, step_norm = |delta| of the step (the tangent step of all blocks);
//     cost = Ceres's (robust) cost times sigma^2, i.e. in mm^2 like the linear solver's;
//   * iterations: LM iterations (accepted and rejected steps); final_cost as history;
//   * rank / condition_number / singular_values: of the shared identifiability check;
//   * covariance: num_parameters square in the parameterization's order (tangent space of each
//     frame's basis, rad and mm), a priori (sigma) or a posteriori (see options); the rows and
//     columns of tools that no measurement uses are zero; empty when not requested, when the
//     solver did not converge, or when ceres::Covariance::Compute() failed (the message says so).
//     With the full parameterization it is the pseudo-inverse (the gauge directions have zero
//     variance). PredictedPositionCovariance (analysis.h) maps it to a configuration.
// Invalid options are programmer errors here (CHECK); tools call ValidateCeresSolverOptions first.
CalibrationResult CalibrateCeres(const RobotModel& nominal, const MeasurementSet& data,
                                 const CeresSolverOptions& options = CeresSolverOptions());

}  // namespace lpoe

#endif  // LPOE_CERES_SOLVER_H_
