// The prior on a calibration's parameters (docs/identifiability.md, "The prior"): a Gaussian on the
// deviation of the estimated model from a reference model, which turns a calibration into a
// maximum-a-posteriori estimate. One mechanism for every use: the default tolerances of a nominal
// model (directions the data determine only weakly stay near the start model), a previous
// calibration's covariance (recalibration) and a fleet's spread (docs/recalibration.md).
//
// Representation, independent of any solver's parameterization:
//   * per local frame f (joints 0..n-1, then tools), the deviation
//       xi_f = log(T_ref,f^-1 T_f)^vee = (omega [rad], v [mm])    in frame f's own coordinates,
//     with a 6x6 information matrix (inverse covariance);
//   * per joint-space term (joint_term.h, by name), its values theta with a reference and a P x P
//     information matrix.
// Each solver maps this into its own coordinates (the basis of the identified directions): the
// linear solver adds the whitened prior rows to its normal equations, the Ceres solver adds one
// prior residual block per frame and per joint block on the same parameter blocks. Both minimise
//     0.5 |y|^2 + 0.5 s^2 sum_f |L_f xi_f|^2 + 0.5 s^2 sum_b |L_b (theta_b - theta_ref,b)|^2
// (y the data residuals in mm, L^T L the information, s the data's standard deviation per axis in
// mm: `data_sigma`, or when that is 0 the a-posteriori value s^2 = 2 cost_data / (rows - params)
// at the solution, a fixed point both solvers reach).
#ifndef LPOE_PRIOR_H_
#define LPOE_PRIOR_H_

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/model/robot_model.h"
#include "lpoe/kinematics/se3.h"

namespace lpoe {

// Standard deviations of the default prior (the tolerances of a nominal model), and how they are
// named by the tools' flags (--prior_translation, ...).
struct PriorScales {
  double frame_translation_mm = 5.0;   // joint frames: position of each axis
  double frame_rotation_mrad = 20.0;   // joint frames: tilts of each axis and the joint zeros
  double tool_translation_mm = 20.0;   // tool points (SMRs) relative to the flange
  double tool_rotation_mrad = 50.0;    // tool orientations (pose data only)
  // Joint-space terms: each parameter's standard deviation is this joint-space effect (RMS over the
  // identification rows of the parameter's regressor column) in mrad.
  double joint_term_mrad = 5.0;
};

struct JointTermPrior {
  std::string name;          // the term's registry name
  Eigen::VectorXd reference; // theta_ref (P values); empty: zero
  Eigen::MatrixXd information;  // P x P; empty: from PriorScales::joint_term_mrad
};

struct ParameterPrior {
  // The model the deviations are measured from; null: the model the solver starts from.
  std::shared_ptr<const RobotModel> reference;
  // Per local frame (joints, then tools): information of xi_f (rad^-2, mm^-2); empty: from scales.
  std::vector<Matrix6d> frame_information;
  std::vector<JointTermPrior> joint_terms;  // terms not listed: from scales
  PriorScales scales;
  // Every standard deviation multiplied by this (--prior_scale); larger is looser.
  double scale = 1.0;
  // The data's standard deviation per axis (mm); 0: estimated from the residuals (see above).
  double data_sigma_mm = 0;
  // An informative prior (a previous calibration, a fleet): the rank and condition refusals judge
  // the data and the prior together (rows that cannot identify the model alone still calibrate).
  // The default tolerance prior is not: data that cannot determine a direction at all are refused.
  bool informative = false;
};

// The default frame information (diagonal) of frame f of `model` from `scales` and `scale`.
Matrix6d DefaultFrameInformation(const RobotModel& model, int f, const PriorScales& scales,
                                 double scale);

// The frame information of frame f: prior.frame_information[f] scaled by 1 / scale^2 when given,
// else the default.
Matrix6d FrameInformation(const ParameterPrior& prior, const RobotModel& model, int f);

// A prior with a reference of its own (a previous calibration, a fleet) used on data of another
// session: the base frame (joint 1's) is that data's registration (the tracker stood elsewhere),
// held by the tolerances only. The directions of the base the parameterization leaves to the next
// frame (those commuting with joint 1's motion: the rotation about and the translation along its
// axis, docs/conventions.md) are registration too: in frame 2's prior (joint 2's frame) they get
// the tolerances, and its other directions keep their marginal information (not the conditional:
// what the earlier calibration knew of them with joint 1's zero unknown). Idempotent.
void FreeRegistrationDirections(const RobotModel& model, ParameterPrior* prior);

// xi_f of `model` against `reference` (both with the same frames).
Vector6d FrameDeviation(const RobotModel& reference, const RobotModel& model, int f);

}  // namespace lpoe

#endif  // LPOE_PRIOR_H_
