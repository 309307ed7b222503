// What defines a calibration problem, declared once (docs/architecture.md, "Options").
//
// The solvers' options and the problem's options contain these structs as their bases, so that a
// field that decides the problem exists once with one default:
//   ProblemDefinitionOptions          the decisions both solvers share
//     <- LinearSolverOptions          (linear_solver.h; its cost is in mm^2: sigma 1, no loss)
//     <- ProblemCostOptions           + sigma and the robust loss
//          <- CeresSolverOptions      (ceres_solver.h)
//          <- CalibrationProblemOptions (problem_builder.h; + rows per residual block)
// A solver hands its share to the problem by assigning the base (slicing), never field by field.
#ifndef LPOE_PROBLEM_OPTIONS_H_
#define LPOE_PROBLEM_OPTIONS_H_

#include <memory>
#include <string>
#include <vector>

#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/prior.h"
#include "lpoe/model/robot_model.h"

namespace lpoe {

using BilinearEffects = std::vector<std::shared_ptr<const BilinearJointEffect>>;

struct ProblemDefinitionOptions {
  ParameterizationKind parameterization = ParameterizationKind::kIdentifiable;
  // Use the measured orientations too (pose-based model, eqs. (17)-(24); pose residuals); requires
  // pose data. Else position residuals.
  bool use_orientation = false;
  // Weight of the orientation residual (rad) against the position residual (mm) in pose mode: an
  // orientation error of 1 rad counts as `orientation_weight` mm. Default: 1000 mm per rad (a 1 m arm).
  double orientation_weight = 1000.0;
  // The chain whose structurally unidentifiable directions are left out
  // (solvers/src/identifiability/structural_identifiability.h); null: the model solved. The pipeline
  // passes the nominal model: registration moves the tools by the noise, so that a tool on the last
  // axis would look slightly off it, and the axis' tilt weakly "identified" from noise. Not owned.
  const RobotModel* structure_reference = nullptr;
  // Joint-space error terms identified with the frames (joint_term.h): each becomes a parameter
  // block reduced to the combinations the data separate from the geometry and from the earlier
  // terms; a combination keeping less than `joint_term_tolerance` of its column's norm (column
  // scaled, once the geometry is projected out) is left out and reported in
  // result.parameterization.unidentifiable.
  std::vector<std::shared_ptr<const JointTerm>> joint_terms;
  double joint_term_tolerance = 1e-4;
  // Effects bilinear with a term of joint_terms, their partner (lpoe/terms/bilinear_term.h; each
  // of a registered block kind, at most one per kind). The gravity tilt (docs/joint_errors.md,
  // "Gravity tilt"): a GravityTiltModel, with "compliance" in joint_terms built on its reference().
  // Their columns vanish where the partner's values are zero, so start from a solution with the
  // partner (initial_joint_terms); one more parameter block each after the joint-space terms'
  // (CalibrationProblem::bilinear_block()). Empty: none (gravity as the model gives it).
  BilinearEffects bilinear_effects;
  // Values of joint_terms to start from (same order and terms; empty: zero).
  std::vector<JointTermValues> initial_joint_terms;
  // A Gaussian prior on the parameters' deviation from a reference model (lpoe/model/prior.h): the solve
  // is then a maximum-a-posteriori estimate; both solvers minimise the same cost (Ceres: one prior
  // residual block per solved frame and joint block). Null: plain least squares. Identifiable
  // parameterization only (the full one stays the paper's pseudo-inverse: CHECKed).
  std::shared_ptr<const ParameterPrior> prior;
};

struct ProblemCostOptions : ProblemDefinitionOptions {
  // Standard deviation of the measurement noise per axis (mm): the residuals are divided by it, so
  // the cost is a chi-square and the covariance is that of the parameters (a priori).
  double sigma = 1.0;
  // Robust loss on each measurement's squared whitened residual: none | huber | cauchy.
  std::string loss = "none";
  // Scale of the robust loss, in mm: errors well below it count as least squares, errors above it
  // are down-weighted. Passed to Ceres as loss_scale / sigma (the residuals are whitened).
  double loss_scale = 1.0;
};

}  // namespace lpoe

#endif  // LPOE_PROBLEM_OPTIONS_H_
