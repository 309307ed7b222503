// Internal to lpoe_solvers: the decisions of a calibration problem, made once (docs/architecture.md,
// "The calibration problem"). CalibrationProblem (problem_builder.h, the Ceres solver's) owns one;
// CalibrateLinear makes its own with the same function. Neither solver decides any of these itself:
// the parameterization (identifiable basis, the joint-space terms' reduction, the gravity tilt), the
// frames solved (tools some row measures), the structure reference, the prior and its reference,
// the count of identifiable unknowns.
#ifndef LPOE_SOLVERS_SRC_CALIBRATION_PROBLEM_SETUP_H_
#define LPOE_SOLVERS_SRC_CALIBRATION_PROBLEM_SETUP_H_

#include <memory>
#include <vector>

#include <Eigen/Core>

#include "linearization/normal_equations.h"
#include "calibration/prior_terms.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/measurements/measurements.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/prior.h"
#include "lpoe/problem_options.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {
namespace internal {

// What decides: the problem's decisions (problem_options.h, the base of both solvers' options and
// of CalibrationProblemOptions) and the directions given.
struct ProblemSetupRequest : ProblemDefinitionOptions {
  // The directions solved, given (frames only; the linear solver's registration and warm start):
  // no reduction, no tools left out, no tilt. Not owned.
  const Parameterization* parameterization_override = nullptr;
};

// The request of a solver's or the problem's options: their decisions, assigned whole.
inline ProblemSetupRequest ProblemSetupRequestOf(const ProblemDefinitionOptions& options) {
  ProblemSetupRequest r;
  static_cast<ProblemDefinitionOptions&>(r) = options;
  return r;
}

struct ProblemSetup {
  // Every frame's basis (unmeasured tools included), the joint blocks, the tilt: the Ceres blocks'
  // numbering (CalibrationProblem::parameterization()).
  Parameterization all;
  // `all` with the tools no row measures left out (listed as not identifiable, with the reason):
  // the numbering both solvers solve and report in (CalibrationResult::parameterization).
  Parameterization solved;
  // Frame f (joints, then tools) is solved: a joint, or a tool some row measures.
  std::vector<bool> frame_solved;
  // Why a requested bilinear block (block_kind.h: the gravity tilt) could not be added (no
  // identified combination of its partner); ok otherwise.
  Status block_status;
  bool full = false;       // the full parameterization (gauge directions solved too)
  bool overridden = false;  // request.parameterization_override
  // The model whose chain decides the structurally unidentifiable directions.
  RobotModel structure;
  int per_row = 3;         // residuals per row: 3 position, 6 pose
  long equations = 0;      // per_row * rows
  // Unknowns the data must determine: solved.num_parameters less the frames' gauge directions
  // still in the basis (full parameterization).
  int identifiable = 0;
  // The joint blocks' coordinates to start from (request.initial_joint_terms; zero otherwise).
  Eigen::VectorXd initial_joint_state;
  // With joint-space terms (no override), the reduction's by-products: the rows' regressors (slot
  // basis of the blocks), the normal equations at the nominal values with every term whole, in
  // analysed_parameterization. Null without terms.
  std::shared_ptr<JointSpaceRegressors> regressors;
  std::shared_ptr<NormalEquations> analysed;
  Parameterization analysed_parameterization;
  // The prior (identifiable parameterization only): anchored (its reference the nominal model
  // unless it has one) and resolved on `solved`. anchored_prior null and prior.active false
  // without one.
  std::shared_ptr<const ParameterPrior> anchored_prior;
  ResolvedPrior prior;
};

// The decisions for a calibration of `nominal` on `data` (the data must fit the model: CHECKed by
// the callers). One pass over the rows with joint-space terms (the reduction), none without.
// The joint-space coordinates (p.num_joint_parameters(), the bilinear blocks' zero) of `initial`
// (values of p's joint blocks' terms, matched by name; empty: zero): x_b = basis_b^T theta_b.
Eigen::VectorXd InitialJointState(const Parameterization& p,
                                  const std::vector<JointTermValues>& initial);

ProblemSetup SetUpProblem(const RobotModel& nominal, const MeasurementSet& data,
                          const ProblemSetupRequest& request);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_SOLVERS_SRC_CALIBRATION_PROBLEM_SETUP_H_
