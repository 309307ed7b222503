// Internal to lpoe_solvers: the identifiability check shared by the linear and the Ceres solver
// (DESIGN.md section 3: data that cannot identify the parameters is refused, never "solved").
#ifndef LPOE_SOLVERS_SRC_IDENTIFIABILITY_H_
#define LPOE_SOLVERS_SRC_IDENTIFIABILITY_H_

#include <string>

#include <Eigen/Core>

#include "lpoe/measurements.h"
#include "lpoe/parameterization.h"
#include "lpoe/robot_model.h"

namespace lpoe {
namespace internal {

// Column scaling D = diag(1 / |column j of J|) from H = J^T J (Jacobi preconditioning): rotation
// columns carry lever arms of ~10^3 mm, translation columns ~1.
Eigen::VectorXd ColumnScale(const Eigen::MatrixXd& H);

struct Identifiability {
  int rank = 0;
  double condition = 0;
  Eigen::VectorXd singular_values;  // of the column-scaled J, descending
  Eigen::VectorXd weakest;          // scaled-parameter direction of the smallest singular value
};

// Numerical rank (relative 1e-8 on singular values, i.e. sqrt(eps) on J^T J) and condition number
// of the column-scaled Jacobian, from H = J^T J.
Identifiability Analyze(const Eigen::MatrixXd& H);

// The (up to) three parameter names carrying most of `v`.
std::string WeakestDirections(const Parameterization& p, const Eigen::VectorXd& v);

// J^T J of the stacked error-model Jacobian at `model`, restricted to p's bases: position rows
// (eq. (29)) or pose rows (eq. (18), rotation rows times orientation_weight). The same matrix, bit
// for bit, as NormalEquationsOf(...).H, so that both solvers' identifiability checks agree exactly.
Eigen::MatrixXd NormalMatrix(const RobotModel& model, const MeasurementSet& data,
                             const Parameterization& p, bool use_orientation,
                             double orientation_weight);

// The linearized problem at one model over all rows (defined in linear_solver.cc).
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
// rotation rows times orientation_weight) and their Jacobian in p's bases, accumulated as normal
// equations. The rows are processed in fixed contiguous chunks (a partition that depends on the row
// count only), possibly on several threads, and the chunks' partial sums are added in order: the
// result is bit-identical whatever the number of threads and their timing. No allocation per row.
NormalEquations NormalEquationsOf(const RobotModel& model, const MeasurementSet& data,
                                  const Parameterization& p, bool use_orientation,
                                  double orientation_weight, bool stack);

// Removes the directions of tools that no row of `data` measures from `p` (listed in
// p->unidentifiable with the reason): they keep their given frames (defined in linear_solver.cc).
void LeaveOutUnmeasuredTools(const RobotModel& model, const MeasurementSet& data,
                             Parameterization* p);

// The messages both solvers give when refusing data.
std::string TooFewEquationsMessage(int rows, long equations, int identifiable, int per_row);
std::string NotIdentifiableMessage(const Identifiability& id, int identifiable,
                                   double max_condition_number, const Parameterization& p);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_SOLVERS_SRC_IDENTIFIABILITY_H_
