// Stopping rules that fit real data (both solvers).
//
// On large-residual data (a real robot leaves 0.1-0.6 mm of non-geometric error after a geometric
// calibration, docs/conventions.md) Gauss-Newton converges only linearly: each step is a fixed
// fraction of the previous one, and an absolute step tolerance of 1e-10 is never reached in a
// useful number of iterations, although the solution has long settled. So a step ends the
// iterations when ANY of these holds:
//   1. absolute:     |x| < step_tolerance                          (the paper's ||x|| < eps)
//   2. statistical:  max_i |x_i| / sd_i < sd_fraction               (sd_i: standard deviation of
//                    parameter i, s^2 (J^T J)^-1 with s^2 = 2 cost / (m - p); a step far below
//                    one standard deviation changes nothing a statistic could see)
//   3. relative:     |x| < relative_step_tolerance * scale          (scale: sqrt(sum |t_f|^2 + F),
//                    the size of the parameters themselves, frame translations in mm and one
//                    radian per frame; Ceres's parameter_tolerance reads the same way)
//   4. cost:         (cost_prev - cost) <= relative_cost_tolerance * cost  (the last accepted step
//                    no longer reduces the cost measurably)
// Noise-free data have sd_i -> 0 and cost -> 0, so rules 2 and 4 never fire early there: they keep
// the quadratic convergence to ~1e-9 mm of exact data.
#ifndef LPOE_CONVERGENCE_H_
#define LPOE_CONVERGENCE_H_

#include <string>

#include <Eigen/Core>

#include "lpoe/model/robot_model.h"

namespace lpoe {

struct ConvergenceOptions {
  double step_tolerance = 1e-10;
  double sd_fraction = 1e-2;
  double relative_step_tolerance = 1e-12;
  double relative_cost_tolerance = 1e-12;
};

// Which rule ended the iterations.
enum class StopRule { kNone, kAbsoluteStep, kStatisticalStep, kRelativeStep, kCost };
const char* StopRuleName(StopRule rule);

// The quantities of one iteration the rules look at.
struct ConvergenceState {
  Eigen::VectorXd step;            // the step x just computed (parameterization's order)
  Eigen::VectorXd standard_deviation;  // of each parameter at the current model; empty: unknown
  double parameter_scale = 1;      // ParameterScale() of the current model
  double cost = 0;                 // current cost
  double previous_cost = -1;       // cost before the last accepted step; < 0 at the first iteration
};

struct ConvergenceDecision {
  StopRule rule = StopRule::kNone;
  double step_norm = 0;            // |x|
  double step_in_sd = 0;           // max_i |x_i| / sd_i (0 when sd unknown)
  std::string message;             // "converged: ..." quoting the figures, when rule != kNone
  bool converged() const { return rule != StopRule::kNone; }
};

ConvergenceDecision TestConvergence(const ConvergenceOptions& options, const ConvergenceState& state);

// sqrt(sum_f |t_f|^2 + F) over the joint and tool frames (mm; one radian per frame).
double ParameterScale(const RobotModel& model);

// Standard deviations from the normal matrix H = J^T J of the current linearization:
// sqrt(diag(s^2 H^-1)), s^2 = 2 cost / dof. Empty when dof <= 0 or H is not positive definite.
Eigen::VectorXd StandardDeviations(const Eigen::MatrixXd& H, double cost, long dof);
// The same from a Cholesky factor the caller already has: L (lower triangle read) with
// L L^T = diag(d) H diag(d) for a positive scale d (any: the result does not depend on it but for
// rounding), e.g. the factor that solved the step.
Eigen::VectorXd StandardDeviationsFromFactor(const Eigen::MatrixXd& L, const Eigen::VectorXd& d,
                                             double cost, long dof);

// (L L^T)^-1 for a lower-triangular L with a positive diagonal (the strict upper triangle is not
// read), e.g. the inverse of a normal matrix from its Cholesky factor: n^3 / 3 multiply-adds (L^-1
// by forward substitution, then L^-T L^-1), exactly symmetric.
Eigen::MatrixXd InverseFromCholeskyFactor(const Eigen::MatrixXd& L);

// Checks the options (user input): finite, step_tolerance > 0 and <= 1, the others in [0, 1).
std::string ValidateConvergenceOptions(const ConvergenceOptions& options);

}  // namespace lpoe

#endif  // LPOE_CONVERGENCE_H_
