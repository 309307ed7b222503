// Internal to lpoe_solvers: the identifiability check shared by the linear and the Ceres solver
// (docs/conventions.md: data that cannot identify the parameters is refused, never "solved").
#ifndef LPOE_SOLVERS_SRC_IDENTIFIABILITY_H_
#define LPOE_SOLVERS_SRC_IDENTIFIABILITY_H_

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/measurements/measurements.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/robot_model.h"
#include "linearization/normal_equations.h"

namespace lpoe {
namespace internal {

// Column scaling D = diag(1 / |column j of J|) from H = J^T J (Jacobi preconditioning): rotation
// columns carry lever arms of ~10^3 mm, translation columns ~1. Columns shorter than
// kRoundOffColumn times the longest are round-off (their directions move nothing): scale 1.
constexpr double kRoundOffColumn = 1e-12;
Eigen::VectorXd ColumnScale(const Eigen::MatrixXd& H);

struct Identifiability {
  int rank = 0;
  double condition = 0;
  Eigen::VectorXd singular_values;  // of the column-scaled J, descending
  Eigen::VectorXd weakest;          // scaled-parameter direction of the smallest singular value
};

// Numerical rank (relative 1e-8 on singular values, i.e. sqrt(eps) on J^T J) and condition number
// of the column-scaled Jacobian, from H = J^T J. `weakest` false: the eigenvalues only (about a
// third of the work), Identifiability::weakest left empty.
Identifiability Analyze(const Eigen::MatrixXd& H, bool weakest = true);

// The (up to) three parameter names carrying most of `v`.
std::string WeakestDirections(const Parameterization& p, const Eigen::VectorXd& v);

// J^T J of the stacked error-model Jacobian at `model` (joint blocks at zero), in p's blocks:
// position rows (eq. (29)) or pose rows (eq. (18), rotation rows times orientation_weight). The
// same matrix, bit for bit, as NormalEquationsOf(...).H, so that both solvers' identifiability
// checks agree exactly.
Eigen::MatrixXd NormalMatrix(const RobotModel& model, const MeasurementSet& data,
                             const Parameterization& p, bool use_orientation,
                             double orientation_weight);

// What SolverParameterization builds, besides the nominal model and the data it is analysed at
// (the defaults are the solvers' option defaults), and where its by-products go.
struct SolverParameterizationRequest {
  ParameterizationKind kind = ParameterizationKind::kIdentifiable;
  // Pose rows (rotation rows times orientation_weight, mm per rad), else position rows.
  bool use_orientation = false;
  double orientation_weight = 1000.0;
  // The joint-space terms, one block each, in this order.
  std::vector<std::shared_ptr<const JointTerm>> terms;
  // A block's combination is kept when its scaled singular value is at least this.
  double tolerance = 1e-4;
  // The model whose chain decides the structurally unidentifiable directions (null: nominal).
  const RobotModel* structure_reference = nullptr;
  // When `terms` is not empty, the analysis' by-products (each optional): `analysed` its normal
  // equations at nominal (identifiable frames, every joint block whole:
  // `analysed_parameterization`; frames and blocks as in the returned parameterization when `kind`
  // is kIdentifiable), `regressors` the rows' joint-space regressors (slot_basis for the whole
  // blocks).
  NormalEquations* analysed = nullptr;
  JointSpaceRegressors* regressors = nullptr;
  Parameterization* analysed_parameterization = nullptr;
};

// The request of a solver's options (LinearSolverOptions, CalibrationProblemOptions: the same
// field names), without by-products.
template <typename SolverOptions>
SolverParameterizationRequest ParameterizationRequestOf(const SolverOptions& options) {
  SolverParameterizationRequest request;
  request.kind = options.parameterization;
  request.use_orientation = options.use_orientation;
  request.orientation_weight = options.orientation_weight;
  request.terms = options.joint_terms;
  request.tolerance = options.joint_term_tolerance;
  request.structure_reference = options.structure_reference;
  return request;
}

// The solved parameterization of both solvers: the frame blocks of `kind` for the data's kind, then
// one joint-space block per term, each reduced to the combinations of its parameters that `data`
// separate from the identifiable geometry and from the earlier terms at `nominal` (the Schur
// complement of the block in the column-scaled normal matrix; a combination whose scaled singular
// value is below `tolerance`, i.e. which keeps less than that fraction of its column's norm once
// the geometry and the earlier blocks are projected out, is left out and listed in
// p.unidentifiable). A block with nothing left keeps zero columns.
Parameterization SolverParameterization(const RobotModel& nominal, const MeasurementSet& data,
                                        const SolverParameterizationRequest& request);

// The analysis of SolverParameterization on the normal matrix H of `pi` (identifiable frames, then
// every joint block whole): per block, the basis of the combinations kept.
std::vector<Eigen::MatrixXd> JointBlockBases(const Eigen::MatrixXd& H, const Parameterization& pi,
                                             double tolerance);

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
