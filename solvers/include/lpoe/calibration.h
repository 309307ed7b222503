// Calibration: identify the local frames of a robot model (and, optionally, joint-space error terms,
// joint_term.h) from measurements. Two solvers sit behind one result type, and assemble their
// problem from the same list of parameter blocks (parameterization.h) and measurement kinds
// (measurement_model.h):
//   * the paper's linearized iterative least squares (pose-based eqs. (17)-(24), position-based
//     eqs. (26)-(32)), in linear_solver.h;
//   * a Ceres problem with an SE(3) manifold per local frame, in ceres_solver.h.
#ifndef LPOE_CALIBRATION_H_
#define LPOE_CALIBRATION_H_

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/terms/joint_term.h"
#include "lpoe/convergence.h"
#include "lpoe/measurements/measurements.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/model/statistics.h"

namespace lpoe {

// One row of the convergence history (the paper's Fig. 6). Errors are those of the model *before*
// the step of this iteration is applied, on the identification data; the last record is the final
// model, whose step_norm is the step found below the tolerance (not applied).
struct IterationRecord {
  int iteration = 0;
  double cost = 0;        // 0.5 * sum of squared residuals (mm^2; pose data mixes rad^2)
  double max_error = 0;   // mm, largest position error norm
  double mean_error = 0;  // mm, mean position error norm
  double step_norm = 0;   // ||x|| of the update computed at this iteration
  // The rows of this record's linearization when they are a subsample (the linear solver's warm
  // start, linear_solver.h: cost and errors are those of these rows); 0: all rows.
  int rows = 0;
};

enum class Termination {
  kConverged,          // ||x|| < eps (linear) or a Ceres convergence criterion
  kMaxIterations,      // stopped at the iteration limit without converging
  kNotIdentifiable,    // too few rows or degenerate poses: nothing was solved
  kNumericalFailure,   // non-finite values or a step that could not reduce the cost
};

const char* TerminationName(Termination t);

// The gravity tilt (docs/joint_errors.md, "Gravity tilt"): two small rotations of the model's
// gravity about axes perpendicular to it, identified with the compliance term.
struct GravityTiltResult {
  bool requested = false;   // asked for (joint_errors "tilt")
  bool identified = false;  // solved (the data determine it)
  Eigen::Vector2d tilt = Eigen::Vector2d::Zero();                // rad, about axes.col(0), col(1)
  // rad (0: no covariance). A posteriori for both solvers (the noise estimated from the
  // residuals, s^2 = 2 cost / (m - p): the linear solver's covariance, and the form of
  // predicted_standard_deviation), so that the solvers' tilts and the check compare directly.
  Eigen::Vector2d standard_deviation = Eigen::Vector2d::Zero();
  // The a-priori form (noise = the solver's sigma), when the solver's covariance is a priori
  // (Ceres with sigma given: its other parameters' standard deviations are in this form); zero
  // otherwise.
  Eigen::Vector2d a_priori_standard_deviation = Eigen::Vector2d::Zero();
  Eigen::Matrix<double, 3, 2> axes = Eigen::Matrix<double, 3, 2>::Zero();  // model base frame
  Eigen::Vector3d gravity_before = Eigen::Vector3d::Zero();  // the model's (start) gravity
  Eigen::Vector3d gravity_after = Eigen::Vector3d::Zero();   // tilted (the calibrated model's)
  // The identifiability check before solving: smallest kept fraction of the tilt's column-scaled
  // columns once everything else is projected out, and the predicted standard deviations (rad).
  double kept_fraction = 0;
  Eigen::Vector2d predicted_standard_deviation = Eigen::Vector2d::Zero();
  std::string message;  // why it was not identified (empty when it was)
};

struct CalibrationResult {
  Termination termination = Termination::kNumericalFailure;
  std::string message;  // one line a user can act on
  RobotModel model;     // the calibrated model (the input model when nothing was solved)
  // Identified values of the joint-space terms (options.joint_terms, same order; theta of the
  // combinations left out is zero). Predict with measurement_model.h PredictPosition(model,
  // joint_terms, q).
  std::vector<JointTermValues> joint_terms;
  Parameterization parameterization;
  std::vector<IterationRecord> history;
  int iterations = 0;
  double final_cost = 0;
  // Rows of the linear solver's warm-start subsample when one was used (linear_solver.h); 0: none.
  int warm_start_rows = 0;
  // The rule of convergence.h that ended the iterations (kNone unless converged by it; a Ceres
  // criterion of its own also leaves kNone).
  StopRule stop_rule = StopRule::kNone;

  // Identifiability of the linearized problem at the nominal model (column-scaled Jacobian).
  int rank = 0;
  double condition_number = 0;
  Eigen::VectorXd singular_values;  // of the column-scaled Jacobian, descending

  // Covariance of the identified parameters in the tangent space (num_parameters square), when the
  // solver computed one (mm / rad units of the basis). Empty otherwise.
  Eigen::MatrixXd covariance;
  double wall_time_seconds = 0;
  GravityTiltResult gravity_tilt;

  // The prior (lpoe/model/prior.h, docs/identifiability.md) when the solve used one; empty otherwise.
  // Per parameter: the prior's standard deviation (x units; infinity without one) and the data's
  // share of the information, 1 - posterior variance / prior variance (1: the data alone; near 0:
  // the prior holds the direction, "weakly determined"). `covariance` is the posterior's.
  Eigen::VectorXd prior_standard_deviation;
  Eigen::VectorXd data_share;
  double prior_data_sigma = 0;  // s (mm per axis) the prior was weighted with
  double prior_cost = 0;        // 0.5 s^2 |L xi|^2 at the solution (mm^2); not in final_cost
  bool has_prior() const { return data_share.size() > 0; }

  bool converged() const { return termination == Termination::kConverged; }
};

}  // namespace lpoe

#endif  // LPOE_CALIBRATION_H_
