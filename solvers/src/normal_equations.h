// Internal to lpoe_solvers: the linearized problem over all rows, accumulated as normal equations,
// for any measurement kind and any list of parameter blocks (frames and joint-space terms). Used by
// the linear solver's iterations and by the identifiability analysis both solvers share.
#ifndef LPOE_SOLVERS_SRC_NORMAL_EQUATIONS_H_
#define LPOE_SOLVERS_SRC_NORMAL_EQUATIONS_H_

#include <Eigen/Core>

#include "lpoe/measurements.h"
#include "lpoe/parameterization.h"
#include "lpoe/robot_model.h"
#include "lpoe/statistics.h"

namespace lpoe {
namespace internal {

struct NormalEquations {
  Eigen::MatrixXd H;      // J^T J (num_parameters square)
  Eigen::VectorXd g;      // J^T y
  Eigen::MatrixXd J;      // stacked J, only when asked for (`stack`)
  Eigen::VectorXd y;      // stacked y, only when asked for
  double cost = 0;        // 0.5 |y|^2
  double max_error = 0;   // mm, position error norm
  double mean_error = 0;  // mm
  bool finite = true;
};

// Residuals y (position: P_measured - P_model, eq. (30); pose: log(T_measured T_model^-1), eq. (17),
// rotation rows times orientation_weight) and their Jacobian in p's blocks, accumulated as normal
// equations, at the frames of `model` and the joint-block coordinates `joint_state`
// (p.num_joint_parameters() values; empty means zero): each row is evaluated at
// q_eff = q + sum_b Y_b(q) basis_b x_b, and a joint block's columns are J_q(q_eff) Y_b(q) basis_b.
// The rows are processed in fixed contiguous chunks (a partition that depends on the row count
// only), possibly on several threads, and the chunks' partial sums are added in order: the result
// is bit-identical whatever the number of threads and their timing. No allocation per row.
// `joint_rows`, when given and not empty, holds every row's R = [Y_b(q) basis_b] (JointRegressorRows
// of the same p and data): the rows' regressors are then read, not evaluated (same result, bit for
// bit).
// `errors`, when given, receives the position errors of every row (PositionErrorRows, replaced) for
// position data without joint-space blocks; it is left alone otherwise.
NormalEquations NormalEquationsOf(const RobotModel& model, const MeasurementSet& data,
                                  const Parameterization& p, const Eigen::VectorXd& joint_state,
                                  bool use_orientation, double orientation_weight, bool stack,
                                  const Eigen::MatrixXd* joint_rows = nullptr,
                                  PositionErrorRows* errors = nullptr);

// Largest cache JointRegressorRows builds (bytes); above it the regressors are evaluated per row at
// every linearization.
constexpr double kMaxJointRowsBytes = 256.0 * 1024 * 1024;

// The joint regressors R = [Y_b(q) basis_b] (n x K) of every row of `data`, side by side
// (n x K * rows, row r in columns [r K, (r + 1) K)): they depend on the joint values and on p's
// bases only, not on the calibration state, so a solver evaluates them once per solve. Empty when p
// has no joint-space blocks or the cache would exceed kMaxJointRowsBytes.
Eigen::MatrixXd JointRegressorRows(const Parameterization& p, const MeasurementSet& data);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_SOLVERS_SRC_NORMAL_EQUATIONS_H_
