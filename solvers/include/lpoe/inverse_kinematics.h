// Inverse kinematics on a (calibrated) LPoE model: the joint values that put a tool at a target
// position (3-D) or pose (6-D), found by damped Newton (Levenberg-Marquardt) iterations from a seed.
//
// Task error (world-aligned at the tool point, rows position then orientation):
//   e = [p_target - p(q);  log(R_target R(q)^T)^vee]      (mm; rad)
// Joint Jacobian (KinematicChain::ToolJointJacobian, one forward sweep): joint j's spatial axis at q
// is Ad_{G_j} s_j with G_j = T_0,j-1(q) T_{j-1,j}(0), so with G_j = (R, t) and s_j = (omega, v):
//   w_j = R omega,   dp/dq_j = w_j x (p - t) + R v,   drot/dq_j = w_j.
//
// Step (one formula for square and redundant tasks): with r = seed - q (the way back to the seed),
// J_w = W J (orientation rows weighted by a length, W = diag(1, 1, 1, L, L, L)),
//   d = beta r + J_w^T (J_w J_w^T + lambda^2 I)^-1 (W e - beta J_w r),
// which for lambda -> 0 is the step that solves the linearized task exactly and, among those, ends
// closest to the seed (minimum-norm step plus the null-space projection of r). Its fixed points
// are the configurations that reach the target at the smallest Euclidean distance from the seed
// in joint values (rad and mm as they are). lambda is Levenberg-Marquardt damping, zero while steps
// reduce |W e|, raised (and beta halved) when a step does not; a trust region caps each step.
//
// Joint limits: a step that would leave [lower, upper] is cut at the limit and that joint is held
// there for the rest of the step (active set, recomputed every iteration), so no iterate leaves the
// limits.
//
// Joint-space error terms (q_eff = q + dq(q), prediction = FK(q_eff)) enter through an
// EffectiveJointMap object: the chain is evaluated at q_eff = g(q) and the Jacobian is J(q_eff) dg/dq.
// By default that is the model's own joint-error terms (RobotModel::joint_errors: compliance,
// harmonics), so a calibrated model is inverted with everything it predicts with.
//
// Configuration branch (arms with 6 or more revolute joints): the signs of
//   D_arm   = det [dc/dq_1, dc/dq_2, dc/dq_3], c the origin of joint n-1's frame (the wrist's middle
//             joint; for spherical and UR-type wrists a point on the last axes). It vanishes at the
//             shoulder and elbow singularities (c on joint 1's axis, elbow stretched or folded).
//   D_wrist = w_{n-2} . (w_{n-1} x w_n), the last three joint axes. It vanishes at the wrist
//             singularity (first and last wrist axes aligned).
// A solution whose signs differ from the seed's crossed a singular surface: another branch of the
// inverse (elbow up/down, wrist flip, shoulder left/right) than the program was planned on.
//
// A residual layer the model carries (RobotModel::residual_layer, a position correction m(q, tool))
// is inverted by fixed-point iteration on the target: q_{k+1} solves FK(g(q)) = p_target -
// m(q_k, tool) from the same seed, until the layered prediction FK(g(q)) + m(q) reaches p_target.
// The map contracts by about |dm/dq| / |dp/dq| (1e-4 for a correction of 0.1 mm over a radian on
// an arm of 500 mm), so two or three solves suffice.
#ifndef LPOE_INVERSE_KINEMATICS_H_
#define LPOE_INVERSE_KINEMATICS_H_

#include <memory>

#include <Eigen/Core>

#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

// Effective joint values q_eff = g(q) that the kinematic chain sees for commanded joints q, with
// the derivative dg/dq (the model's joint-error terms g(q) = q + Y(q) theta by default, see
// InverseKinematics; any other map, e.g. a coupling, through this interface).
class EffectiveJointMap {
 public:
  virtual ~EffectiveJointMap() = default;
  // Writes g(q) into q_eff (n values) and, when dg_dq is not null, dg/dq into dg_dq (n x n,
  // column-major: dg_dq[c * n + r] = d g_r / d q_c). n is the model's joint count.
  virtual void Evaluate(const double* q, double* q_eff, double* dg_dq) const = 0;
};

enum class IkStatus {
  kOk,           // reached the target within tolerance, on the seed's branch, not singular
  kUnreachable,  // no joint values within the limits reach the target (best found returned)
  kLimit,        // not reached, and a joint limit cut the way there (some step was stopped)
  kSingular,     // at or stuck near a singularity: smallest singular value below the threshold
  kBranch,       // reached, but on another configuration branch than the seed's
};
const char* IkStatusName(IkStatus status);

struct IkTarget {
  int tool = 0;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // mm, model (base/measurement) frame
  bool has_orientation = false;                        // pose target when true
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();  // tool frame in the model frame
};

struct IkOptions {
  int max_iterations = 100;
  double position_tolerance = 1e-7;      // mm
  double orientation_tolerance = 1e-10;  // rad
  // Redundant tasks: converged when, besides the task tolerances, the step toward the seed (the
  // null-space part) is below this (rad / mm).
  double step_tolerance = 1e-10;
  // Length L weighting the orientation rows against the position rows (mm per rad).
  double orientation_weight = 100.0;
  // Smallest singular value of the weighted task Jacobian (mm per rad or mm) below which a
  // configuration counts as singular.
  double singular_threshold = 1e-3;
  // Largest change of a revolute (rad) / prismatic (mm) joint in one iteration.
  double max_step_revolute = 0.5;
  double max_step_prismatic = 50.0;
  bool respect_limits = true;
  bool check_branch = true;
  // When a solve stalls (a local minimum of the error, typically near a singularity or a limit),
  // restart from the seed perturbed by up to restart_step * k rad (k = 1..restarts; 10 mm per rad
  // for prismatic joints), deterministic, and keep the reached solution closest to the seed.
  int restarts = 8;
  double restart_step = 0.05;
};

struct IkResult {
  IkStatus status = IkStatus::kUnreachable;
  double position_error = 0;     // mm, |p_target - p(q)| at the returned q
  double orientation_error = 0;  // rad, pose targets
  double sigma_min = 0;          // smallest singular value of the weighted task Jacobian at q
  double correction = 0;         // |q - seed|, Euclidean in rad and mm
  int iterations = 0;             // over all attempts
  int restarts = 0;               // restarts used
  bool at_limit = false;         // a joint held at a limit in the last step
  bool branch_changed = false;
};

// The solver, prepared once per model (Pinocchio-style: refers to `model` and `effective` without
// owning them). Solve() allocates nothing and may be called from several threads at once.
class InverseKinematics {
 public:
  static constexpr int kMaxJoints = 16;

  // Checks that `model` can be solved (1..kMaxJoints joints, valid model); the message says why not.
  static Status CheckModel(const RobotModel& model);

  // `model` must pass CheckModel (CHECKed). `effective` null: the model's own joint-error terms
  // when it carries any (q_eff = q + dq(q), dg/dq by forward differences of dq), else the identity.
  explicit InverseKinematics(const RobotModel& model, const IkOptions& options = IkOptions(),
                             const EffectiveJointMap* effective = nullptr);

  const IkOptions& options() const { return options_; }

  // Solves from `seed` (n values; clamped into the limits) and writes the best joints found to `q`
  // (may alias `seed`).
  IkResult Solve(const IkTarget& target, const double* seed, double* q) const;

  // Branch signs (D_arm, D_wrist) at joint values q (tool irrelevant); zero where undefined (fewer
  // than 6 joints, or a prismatic joint among the ones used).
  void BranchSigns(const double* q, int signs[2]) const;

 private:
  // Solve without the model's residual layer (the chain with its joint-error terms).
  IkResult SolveParametric(const IkTarget& target, const double* seed, double* q) const;
  // With a residual layer m(q, tool) (lpoe/model/residual_layer.h): the chain solved for the target
  // moved by -m at the previous solution until m settles (inverse_kinematics_layer.cc).
  IkResult SolveThroughLayer(const IkTarget& target, const double* seed, double* q) const;
  // M task rows (3 or 6), N joints (6, 7, or Eigen::Dynamic for other counts: fixed-size types for
  // the common arms).
  template <int M, int N>
  IkResult SolveTask(const IkTarget& target, const double* seed, double* q) const;
  // One damped Newton run from `start`, drawn toward `seed` in the null space.
  template <int M, int N>
  IkResult Run(const IkTarget& target, const double* seed, const double* start, double* q) const;

  const RobotModel* model_;
  IkOptions options_;
  const EffectiveJointMap* effective_;
  std::shared_ptr<const EffectiveJointMap> own_effective_;  // the model's joint-error terms
  KinematicChain chain_;
  bool branch_defined_ = false;
  bool z_revolute_[kMaxJoints] = {};  // revolute about local z: sin/cos updated incrementally
};

}  // namespace lpoe

#endif  // LPOE_INVERSE_KINEMATICS_H_
