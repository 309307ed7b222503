// Internal to lpoe_solvers: the solvers on a CalibrationProblem the caller built (the pipeline: one
// problem per solve, whichever solver takes it; docs/architecture.md, "The calibration problem").
// CalibrateLinear(nominal, data, options) and CalibrateCeres(nominal, data, options) are these on
// CalibrationProblem(nominal, data, the options' decisions).
#ifndef LPOE_SOLVERS_SRC_CALIBRATION_SOLVE_ON_PROBLEM_H_
#define LPOE_SOLVERS_SRC_CALIBRATION_SOLVE_ON_PROBLEM_H_

#include "lpoe/calibration.h"
#include "lpoe/ceres_solver.h"
#include "lpoe/linear_solver.h"
#include "lpoe/problem_builder.h"

namespace lpoe {
namespace internal {

// The linear solver on `problem`: every decision is the problem's (its parameterization, structure
// reference, joint-space terms, gravity tilt, prior, measurement kind); the options' fields for
// them are not read. The start is the problem's current values, and the problem is left at the
// returned solution. What the options give is how to solve: iterations, tolerances, covariance,
// warm start, callbacks, errors.
CalibrationResult CalibrateLinearOn(CalibrationProblem* problem, const LinearSolverOptions& options);

// The problem's share of the linear solver's options (its ProblemDefinitionOptions base; sigma 1 and
// no loss: the linear solver's cost is in mm^2).
CalibrationProblemOptions LinearProblemOptions(const LinearSolverOptions& options);

// The problem's share of Ceres's options (the decisions, sigma, the loss) with the rows per
// residual block picked for `rows` rows (rows_per_block 0: 1024 from kBatchFromRows on).
CalibrationProblemOptions CeresProblemOptions(const CeresSolverOptions& options, int rows);
// The Ceres solver on `problem`: every decision is the problem's, and so are sigma, the loss and
// the rows per block; the options' fields for them are not read. The start is the problem's
// current values; the problem is left at the returned solution. Once per problem (its blocks are
// added to a ceres::Problem).
CalibrationResult CalibrateCeresOn(CalibrationProblem* problem, const CeresSolverOptions& options);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_SOLVERS_SRC_CALIBRATION_SOLVE_ON_PROBLEM_H_
