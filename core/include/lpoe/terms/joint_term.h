// Joint-space error terms: non-geometric errors that shift the joint values (docs/architecture.md).
//
// Every term is linear in its parameters theta (P numbers):
//
//   dq = Y(q) theta,   Y: num_joints x P (the term's regressor at the joint values q read or
//                      commanded for the measurement),
//   q_eff = q + sum_terms Y_term(q) theta_term,   P_model = FK(q_eff) p_tool.
//
// Y is evaluated from the term's own reference geometry (for a gravity term: the nominal, registered
// start model), fixed when the term is built, so both solvers see Y as data and minimise the same
// cost. The chain rule gives the Jacobian columns: dP/dtheta = J_q(q_eff) Y(q), with J_q the
// position Jacobian with respect to the joint values (kinematics.h ToolPositionJointJacobian).
//
// A new term is one source file that defines a JointTerm and its factory, plus one line in
// core/src/terms/joint_term_registry.inc. Which combinations of theta the data can separate from the
// geometry and from the other terms is decided by the solvers (Parameterization::joint_blocks).
#ifndef LPOE_JOINT_TERM_H_
#define LPOE_JOINT_TERM_H_

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/measurements/measurements.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

class JointTerm {
 public:
  virtual ~JointTerm() = default;

  // Short name, used as the prefix of the parameter names ("compliance", "harmonics").
  virtual std::string name() const = 0;
  // Joints of the robot the term was built for.
  virtual int num_joints() const = 0;
  // P, the number of parameters theta.
  virtual int num_parameters() const = 0;
  // Readable name of parameter k, e.g. "joint2.a1".
  virtual std::string ParameterName(int k) const = 0;
  // Y(q): num_joints() x num_parameters(), column-major (Y[k * num_joints() + j] = dq_j/dtheta_k),
  // at the joint values `q` (num_joints() values). Must depend on q only (not on the calibration
  // state): the solvers may evaluate it once per row or again at every iteration.
  virtual void Regressor(const double* q, double* Y) const = 0;
  // The one joint that parameter k can move (row of Y's column k that may be non-zero; every other
  // row is zero at every q), or -1 when it may move several joints. The solvers use it to form the
  // normal equations from Y's sparsity (solvers/src/linearization/normal_equations.h) and check it on every
  // regressor they evaluate. The default, -1 for every parameter, is always correct.
  virtual int ParameterJoint(int k) const {
    (void)k;
    return -1;
  }
  // Optional fast path for a term whose every parameter moves one joint (ParameterJoint(k) >= 0 for
  // every k): y[k] = Y(ParameterJoint(k), k) at `q` (num_parameters() values), the only entries of Y
  // that can be non-zero, exactly equal to Regressor's. The solvers then read these instead of
  // forming Y for every row. Returns false (the default) when the term does not provide it.
  virtual bool RegressorValues(const double* q, double* y) const {
    (void)q;
    (void)y;
    return false;
  }
};

// A term with identified values.
struct JointTermValues {
  std::shared_ptr<const JointTerm> term;
  Eigen::VectorXd theta;  // term->num_parameters() values
};

// q_eff = q + sum Y(q) theta (num_joints values each).
void EffectiveJointValues(const std::vector<JointTermValues>& terms, int num_joints,
                          const double* q, double* q_eff);

// The measurements with every row's joint values replaced by q_eff: what FK-based code (statistics,
// plots, registration) evaluates to predict with the terms.
MeasurementSet WithEffectiveJointValues(const std::vector<JointTermValues>& terms,
                                        const MeasurementSet& data);

// ---- Registry: the terms a user can ask for by name.
//
// One registry (core/src/terms/joint_term_registry.inc) lists every joint-space term. Its entry
// (core/src/terms/joint_term_kind.h) owns the term's name, parameter layout and names, regressor, the
// offsets a model carrying the term predicts with, its YAML block under `joint_errors` and its
// simulated truth values. Everything else (both solvers, prediction, IK, planning, simulation, the
// tools and the Python module) goes through the functions below and never names a term.

// Builds a term by name for `reference` (the nominal, registered model): its regressor is evaluated
// on `reference`'s geometry.
Status MakeJointTerm(const std::string& name, const RobotModel& reference,
                     std::shared_ptr<const JointTerm>* term);
// The names MakeJointTerm accepts, in registry order.
std::vector<std::string> JointTermNames();
// True when `name` is in the registry.
bool IsJointTermName(const std::string& name);
// `names` (each a registry name) sorted into registry order.
std::vector<std::string> InRegistryOrder(const std::vector<std::string>& names);
// "compliance, harmonics, ..." (the registry's names, for messages).
std::string JointTermNameList();

// The number of parameters and their names of term `name` on `model` (CHECK-fails on an unknown
// name: check it with IsJointTermName first).
int NumJointErrorParameters(const RobotModel& model, const std::string& name);
std::vector<std::string> JointErrorParameterNames(const RobotModel& model,
                                                  const std::string& name);
// The term's regressor Y(q) (num_joints x NumJointErrorParameters) on `model`'s own geometry,
// rounding noise set to zero (kJointErrorRoundingCutoff of joint_errors.h).
void JointErrorRegressor(const RobotModel& model, const std::string& name, const double* q,
                         Eigen::MatrixXd* Y);
// The joint (0-based) each parameter of term `name` moves, -1 when it may move several.
std::vector<int> JointErrorParameterJoints(const RobotModel& model, const std::string& name);

}  // namespace lpoe

#endif  // LPOE_JOINT_TERM_H_
