// The Local Product of Exponentials robot model (paper eqs. (1), (6), (7)):
//
//   T_0,tool(q) = T_0,1(0) exp(s_1^ q_1) T_1,2(0) exp(s_2^ q_2) ... T_n-1,n(0) exp(s_n^ q_n) T_n,tool
//
// Each joint i has a local frame T_{i-1,i}(0) (its "origin", in the parent's coordinates) and a fixed
// twist s_i = (omega, v) expressed in its own frame. Tools are frames fixed to the last link; a laser
// tracker measures the origin of a tool (a retro-reflector) and, for pose data, its orientation.
//
// All kinematic errors live in the local frames (paper section 3.1): the calibration parameters are
// the n joint origins and the tool origins, each perturbed on the right (eq. (19)).
#ifndef LPOE_ROBOT_MODEL_H_
#define LPOE_ROBOT_MODEL_H_

#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "lpoe/kinematics/se3.h"
#include "lpoe/status.h"

namespace lpoe {

enum class JointType { kRevolute, kPrismatic };

const char* JointTypeName(JointType type);

struct Joint {
  std::string name;
  JointType type = JointType::kRevolute;
  SE3d origin;                                                // T_{i-1,i}(0)
  Vector6d twist = (Vector6d() << 0, 0, 1, 0, 0, 0).finished();  // (omega, v) in the joint frame
  // Joint limits (rad for revolute, mm for prismatic joints); infinite when the model gives none.
  double lower = -std::numeric_limits<double>::infinity();
  double upper = std::numeric_limits<double>::infinity();
  bool has_limits() const { return std::isfinite(lower) || std::isfinite(upper); }
};

struct Tool {
  std::string name;
  SE3d origin;  // T_{n,tool}, in the last joint's frame
  // A known tool frame (an SMR nest whose position on the flange is known from the fixture's
  // drawing or a CMM; YAML `fixed: true`, lpoe_calibrate --fixed_tools): a calibration holds it as
  // given, so that the last joint's frame is identified in full (its zero and its translation along
  // the axis included) instead of being a convention traded against the tool offsets
  // (docs/identifiability.md, "Known SMR nests").
  bool fixed = false;
};

// An optional payload fixed to the flange (the last joint's frame). Its weight enters the gravity
// torques of the compliance term (lpoe/terms/joint_errors.h, docs/joint_errors.md).
struct Payload {
  double mass = 0;                                // kg; 0 means no payload
  Eigen::Vector3d com = Eigen::Vector3d::Zero();  // centre of mass, mm, in the last joint's frame
};

// One joint-space error term a model carries (lpoe/terms/joint_term.h): the registry name of the term
// ("compliance", "harmonics", ...; JointTermNames()) and its parameter values in the term's layout
// (JointTermParameterNames(name, model); JointTermNumParameters(name, model) numbers).
struct JointTermEntry {
  std::string name;
  std::vector<double> values;
  bool operator==(const JointTermEntry& o) const { return name == o.name && values == o.values; }
  bool operator!=(const JointTermEntry& o) const { return !(*this == o); }
};

// Non-geometric joint-space error terms (lpoe/terms/joint_term.h, docs/joint_errors.md). The robot moves
// to the effective joint values q + sum over terms of Y_term(q) theta_term, where the regressors Y
// are evaluated on the model that carries the terms (with `regressor_origins` as its joint origins
// when given). Every term is an entry of the one registry (core/src/terms/joint_term_registry.inc); each
// name at most once (Validate checks both).
struct JointErrorTerms {
  // The terms, each name once; their order does not matter (prediction and YAML follow the
  // registry's order). An entry with no values is an absent term.
  std::vector<JointTermEntry> terms;
  // The joint origins (T_{j-1,j}(0), one per joint) the regressors are evaluated on; empty: the
  // model's own. A calibration stores its registered start model's origins here, the geometry its
  // solver evaluated the regressors on, so that predicting with the calibrated model reproduces the
  // solver's residuals exactly (docs/joint_errors.md).
  std::vector<SE3d> regressor_origins;
  // No term with values.
  bool empty() const;
  // The values of term `name`; an empty vector when the model does not carry it.
  const std::vector<double>& Values(const std::string& name) const;
  // The model carries term `name` (with values).
  bool Has(const std::string& name) const { return !Values(name).empty(); }
  // The values of term `name`, an empty entry appended when the model does not carry it yet.
  std::vector<double>* MutableValues(const std::string& name);
  // Removes term `name` (nothing when absent).
  void Remove(const std::string& name);
};

class ResidualLayer;  // lpoe/model/residual_layer.h

// Standard gravity, m/s^2.
constexpr double kStandardGravity = 9.80665;

// Tolerances used by Validate() on twists.
constexpr double kTwistTolerance = 1e-6;

// A named frame of the robot that is neither a joint nor a tool (docs/conventions.md, "Frames"):
// fixed to the base (ur_description's `base`, the controller's base frame; `world`) or to the last
// link (`tool0`, the controller's flange; `flange`). Targets, programs and predictions may be given
// in a base frame; a TCP is relative to a flange frame. A URDF's links fixed to the chain's base
// link or to its last moving link become such frames; YAML `frames:`. Calibration leaves them as
// they are (a flange frame moves with the last link's calibrated frame, as an unmeasured tool).
struct NamedFrame {
  std::string name;
  bool on_flange = false;  // in the last joint's frame; else in the model's (nominal) base frame
  SE3d pose;
};

class RobotModel {
 public:
  std::string name;
  std::vector<Joint> joints;
  std::vector<Tool> tools;
  // The registration found by calibration: the measurement frame (where this model's base lives,
  // e.g. a laser tracker's) from the nominal model's base frame. Identity when the data were in the
  // base frame. Compensation uses it to carry nominal poses into this model's frame.
  SE3d T_measurement_base;
  // Named base and flange frames (see NamedFrame): base frames are in the nominal base frame (the
  // one T_measurement_base starts from), flange frames in the last joint's frame.
  std::vector<NamedFrame> frames;
  // Gravity in the model's base frame (m/s^2): the parent frame of joint 1's local frame, i.e. the
  // measurement frame of a registered model.
  Eigen::Vector3d gravity = Eigen::Vector3d(0, 0, -kStandardGravity);
  Payload payload;
  JointErrorTerms joint_errors;
  // The learned residual layer (lpoe/model/residual_layer.h, docs/residual_layer.md): a correction of the
  // tool positions over the joint configuration, in this model's base frame, that every prediction
  // (PredictToolPosition, PredictPositions, the inverse kinematics) adds. Null: none. Shared and
  // immutable, so copies of a model are cheap.
  std::shared_ptr<const ResidualLayer> residual_layer;

  int num_joints() const { return static_cast<int>(joints.size()); }
  int num_tools() const { return static_cast<int>(tools.size()); }
  // Local frames that carry calibration parameters: the joint origins, then the tools.
  int num_frames() const { return num_joints() + num_tools(); }

  // Index of the tool called `name`, or -1.
  int FindTool(const std::string& tool_name) const;
  // The named frame called `name` on the base (on_flange false) or on the flange, or null.
  const NamedFrame* FindFrame(const std::string& frame_name, bool on_flange) const;
  // Some tool is fixed (Tool::fixed).
  bool HasFixedTool() const;

  // Checks that the model is usable: at least one joint and one tool, unique names, finite numbers,
  // orthonormal rotations, and twists of the declared type (revolute: |omega| = 1, omega . v = 0;
  // prismatic: omega = 0, |v| = 1), a finite gravity, a payload of finite mass >= 0 and joint-error
  // terms of the right sizes with finite values.
  Status Validate() const;
};

// The checks Validate() makes on one joint's twist (revolute: |omega| = 1, omega . v = 0 within
// kTwistTolerance; prismatic: omega = 0, |v| = 1) and limits (lower <= upper, no NaN). The message
// says what is wrong without saying where; readers add the file and line.
Status ValidateTwist(JointType type, const Vector6d& twist);
Status ValidateLimits(double lower, double upper);

// The default twist of a joint type about/along local z.
Vector6d DefaultTwist(JointType type);

// The nominal "cobot6" of docs/conventions.md (paper Table 1), with one tool at `tool_xyz` (mm) in the
// joint-6 frame.
RobotModel MakeCobot6(const Eigen::Vector3d& tool_xyz = Eigen::Vector3d(40, 0, 60));

// Builds an LPoE model from standard Denavit-Hartenberg parameters (a, alpha, d, theta offset), one
// row per joint, joints revolute about local z. The frames follow the DH chain:
// T_{i-1,i}(0) = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i) expressed so that joint i turns about the
// z axis of frame i-1 (the DH convention), i.e. the local frame of joint i is DH frame i-1.
struct DhRow {
  double a = 0, alpha = 0, d = 0, theta = 0;
  JointType type = JointType::kRevolute;
};
RobotModel MakeFromStandardDh(const std::string& name, const std::vector<DhRow>& rows,
                              const SE3d& tool);

// A UR5-like arm (standard DH, mm), a 7-joint arm, and a 6-joint arm with a prismatic joint: the
// test robots of the acceptance criteria.
RobotModel MakeUr5Like();
RobotModel MakeSevenJointArm();
RobotModel MakeArmWithPrismatic();

}  // namespace lpoe

#endif  // LPOE_ROBOT_MODEL_H_
