// Internal to lpoe_solvers: the linearized problem over all rows, accumulated as normal equations,
// for any measurement kind and any list of parameter blocks (frames and joint-space terms). Used by
// the linear solver's iterations and by the identifiability analysis both solvers share.
#ifndef LPOE_SOLVERS_SRC_NORMAL_EQUATIONS_H_
#define LPOE_SOLVERS_SRC_NORMAL_EQUATIONS_H_

#include <vector>

#include <Eigen/Core>

#include "lpoe/measurements/measurements.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/model/statistics.h"

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
  bool joint_blocks = true;  // false: H's joint-space blocks were not formed (gradient_only)
  bool four_rows = false;    // the position rows were evaluated four at a time (AVX2 path)
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
//
// Joint-space parameters (p's joint blocks) are handled by their structure unless `stack` or
// `joint.dense` is set or p has a bilinear block (the gravity tilt: its columns change with the
// state, lpoe/terms/bilinear_term.h; that solve takes the dense rows): every joint-space parameter
// acts through the effective joint values, and a row's d(dq)/d(theta) is sparse
// (JointSpaceRegressors), so each row's joint part is written in slot coordinates (J_q col j times
// the slot's regressor entry, S columns beside the frames'), one symmetric rank-k update per block
// of poses gives the frames', the frames x slots and the slots' blocks, mapped to p's joint
// coordinates once per pass (docs/joint_errors.md, Cost), instead of rows with every joint column.
// Same numbers up to rounding.
struct JointSpaceRegressors;
struct JointColumnsOptions {
  // The rows' sparse regressors for p (BuildJointSpaceRegressors, or SetSlotBasis for p after a
  // build with other bases of the same terms); null: built for this call.
  const JointSpaceRegressors* regressors = nullptr;
  // Leave the joint blocks of H (frames x joint and joint x joint) zero: g, the cost and the
  // frames' block stay exact (the linear solver's iterations with frozen joint blocks).
  bool gradient_only = false;
  // Form every row with all its columns (the algebra before the structured path; for tests).
  bool dense = false;
  // Position rows four at a time where that path applies (AVX2 and FMA, every joint revolute about
  // z, every frame basis column canonical), the slots' blocks from per-pose J_q products as matrix
  // products over the poses (docs/joint_errors.md, Cost); false: one row at a time with the slot
  // columns (the same numbers up to rounding; for tests).
  bool four_rows = true;
};
// How NormalEquationsOf linearizes, besides where (model, data, p, joint_state). The defaults:
// position rows, the joint regressors evaluated, the joint blocks by their structure.
struct NormalEquationsOptions {
  // Pose data: the rotation rows too, times orientation_weight (mm per rad).
  bool use_orientation = false;
  double orientation_weight = 1.0;
  // Keep the stacked rows (NormalEquations::J and y, data.size() * (3 or 6) rows).
  bool stack = false;
  // Every row's joint regressors, or null (above).
  const Eigen::MatrixXd* joint_rows = nullptr;
  // Receives the rows' position errors, or null (above).
  PositionErrorRows* errors = nullptr;
  JointColumnsOptions joint;
};
NormalEquations NormalEquationsOf(const RobotModel& model, const MeasurementSet& data,
                                  const Parameterization& p, const Eigen::VectorXd& joint_state,
                                  const NormalEquationsOptions& options = NormalEquationsOptions());

// Joint-space parameters with a per-row sparse d(dq)/d(theta), in "slots". The unreduced columns are
// every joint block's own parameters side by side (block b from column_offset[b]); joint j's row of
// d(dq)/d(theta) may be non-zero only in its slots [slot_begin[j], slot_begin[j + 1]), slot s
// standing for unreduced column slot_column[s] (JointTerm::ParameterJoint: one slot for a parameter
// that moves one joint, one per joint for a parameter that may move several). values(s, r) is the
// entry of row r; slot_basis (slots x K) maps p's joint coordinates x to the slots' parameter
// values (row s: block basis row of slot_column[s]), so dq_j = sum_{s in j} values(s, r) *
// (slot_basis x)(s) and a row's joint columns are sum_{s in j} J_q col j * values(s, r) *
// slot_basis row s. Extension point: a joint-space column group whose d(dq)/d(theta) depends on the
// calibration state (e.g. a gravity tilt acting through the compliance torque) appends its slots and
// refills its rows of `values` before each linearization; the accumulation is the same.
struct JointSpaceRegressors {
  int num_joints = 0;
  std::vector<int> column_offset;  // joint blocks + 1
  // Per joint block: every parameter moves one joint (JointTerm::ParameterJoint >= 0), so that the
  // term's RegressorValues may give a row's entries; decided once here, not per row. Empty or
  // false: the block's full regressor is evaluated.
  std::vector<char> one_joint_each;
  std::vector<int> slot_begin;     // num_joints + 1
  std::vector<int> slot_column;    // per slot
  Eigen::MatrixXd values;          // slots x rows; empty when above kMaxJointRowsBytes (evaluated
                                   // per row and linearization)
  Eigen::MatrixXd slot_basis;      // slots x K
  int num_slots() const { return static_cast<int>(slot_column.size()); }
  int num_columns() const { return column_offset.empty() ? 0 : column_offset.back(); }
};

// The slots of p's joint blocks over the rows of `data`, with slot_basis for p. Slots that are zero
// in every row (a joint that feels no gravity torque) are dropped when the values are stored. Checks
// every evaluated regressor against JointTerm::ParameterJoint.
JointSpaceRegressors BuildJointSpaceRegressors(const Parameterization& p,
                                               const MeasurementSet& data);
// Sets r->slot_basis for p, whose joint blocks are the same terms as r was built for.
void SetSlotBasis(const Parameterization& p, JointSpaceRegressors* r);

// The normal equations of `reduced` from those of `full` (same frames, same joint-space terms,
// every block with the identity basis): H_reduced = T^T H_full T, g_reduced = T^T g_full, with T
// the identity on the frames and the blocks' bases of `reduced`. Cost and errors are copied.
NormalEquations ProjectJointBlocks(const NormalEquations& full, const Parameterization& reduced);

// Whether a and b have the same frame directions (blocks, offsets and bases): ProjectJointBlocks
// applies between them.
bool SameFrameDirections(const Parameterization& a, const Parameterization& b);

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
