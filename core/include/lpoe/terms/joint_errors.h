// Non-geometric joint-space error terms (docs/joint_errors.md): the mathematics of the compliance
// under gravity and of the joint harmonics, prediction with every term a model carries, and the
// identifiability analysis. The terms themselves are entries of the one registry (lpoe/terms/joint_term.h,
// core/src/terms/joint_term_registry.inc); this header never lists them. Every term is linear in its
// parameters,
//
//   dq = Y(q) theta,        q_eff = q + sum over terms of Y_term(q) theta_term,
//   P  = FK(q_eff) * tool,
//
// with a regressor Y (num_joints x P) that depends only on the commanded joints q and on the model it
// is evaluated on (geometry, gravity, payload). The solvers evaluate Y once on the registered start
// model and treat it as data; a model that carries identified terms evaluates Y on itself.
//
// Compliance. Joint j turns by c_j tau_j(q), tau_j the gravity torque about j's axis from the links it
// moves (k >= j) and the payload. Link k is the body moved by joint k; its frame is
// T_0,k(q) = T_0,1(0) exp(s_1^ q_1) ... T_k-1,k(0) exp(s_k^ q_k). With (w_j, v_j) joint j's twist in
// the base frame at q, (R_k, t_k) link k's frame, g gravity (m/s^2) in the base frame, m_k the link's
// mass (kg) and h_k = m_k com_k its first moment (kg mm, link k coordinates):
//
//   tau_j = s * sum_{k >= j} [ ((g x w_j) . t_k + v_j . g) m_k + (R_k^T (g x w_j)) . h_k ]
//           + s * m_p [ (g x w_j) . t_n + v_j . g + (R_n^T (g x w_j)) . com_p ]   (payload)
//
// in N m for a revolute joint (s = 1e-3: lengths in mm) and N along the axis for a prismatic one
// (w_j = 0, s = 1). The masses are unknown, so the parameters are the products c_j m_k and c_j h_k
// (4 per joint-link pair) and, for the known payload, c_j itself. Compliance c_j is in rad/(N m) for
// a revolute joint and mm/N for a prismatic one.
//
// Harmonics. dq_j = a1 sin q_j + b1 cos q_j + a2 sin 2q_j + b2 cos 2q_j (revolute joints only; the
// columns of a prismatic joint are zero).
//
// Not every parameter is identifiable: ReduceJointErrorTerms finds the combinations the data can
// separate from the geometric model and from the terms before them.
#ifndef LPOE_JOINT_ERRORS_H_
#define LPOE_JOINT_ERRORS_H_

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/measurements/measurements.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/kinematics/se3.h"
#include "lpoe/status.h"
#include "lpoe/terms/bilinear_term.h"

namespace lpoe {

// Parses a comma-separated list of registry term names (JointTermNames(): "compliance",
// "harmonics", ...), each at most once, in the order given. "none" or an empty text gives an empty
// list. Returns false (and `error`) on anything else.
bool ParseJointTermList(const std::string& text, std::vector<std::string>* names,
                        std::string* error);

// The gravity tilt's name in a list of joint errors ("compliance,tilt"; docs/joint_errors.md). It
// is not a term of its own: it makes the compliance term bilinear (TiltedGravity below).
constexpr const char kGravityTiltName[] = "tilt";
constexpr const char kGravityTiltNeedsCompliance[] =
    "the gravity tilt ('tilt' in the joint errors) is identified with the compliance term and "
    "needs it in the list, e.g. compliance,tilt or compliance,harmonics,tilt";

// ---- Parameter layout of the compliance and harmonics terms (their values in
// RobotModel::joint_errors, see robot_model.h).

// sum over j of 4 (n - j) + 1.
int NumComplianceParameters(int num_joints);
// Index of c_j m_k (then c_j h_k x, y, z follow), 0-based joint j <= link k.
int ComplianceLinkIndex(int num_joints, int joint, int link);
// Index of c_j (the payload's column).
int CompliancePayloadIndex(int num_joints, int joint);
constexpr int kHarmonicsPerJoint = 4;
int NumHarmonicsParameters(int num_joints);

// Checks gravity, payload and the joint-error terms (called by Validate): every term a registry
// name, at most once, with the term's number of finite values.
Status ValidateJointErrorTerms(const RobotModel& model);

// ---- Regressors of compliance and harmonics: Y is resized to num_joints x P and overwritten.
// (Any term's regressor by name: JointErrorRegressor of joint_term.h.)

void ComplianceRegressor(const RobotModel& model, const double* q, Eigen::MatrixXd* Y);
// The compliance regressor is linear in the gravity vector: Y(g) = sum_a g_a Y_a. Fills Y_a for the
// three base axes (for identifying a tilt of gravity, see TiltedGravity).
void ComplianceRegressorGravityAxes(const RobotModel& model, const double* q, Eigen::MatrixXd Y[3]);
// The same three regressors' only entries that can be non-zero, without the num_joints x P
// matrices: y[a][c] = Y_a(joint of c, c) for c < NumComplianceParameters (joint j's parameters are
// ComplianceLinkIndex(n, j, j) .. CompliancePayloadIndex(n, j)). What the solvers evaluate per row.
void ComplianceValuesGravityAxes(const RobotModel& model, const double* q, double* const y[3]);
void HarmonicsRegressor(const RobotModel& model, const double* q, Eigen::MatrixXd* Y);
// Entries below this fraction of the largest |Y| at a configuration are set to zero by
// JointErrorRegressor and JointErrorOffsets (rounding noise, e.g. the gravity torque about a
// vertical axis).
constexpr double kJointErrorRoundingCutoff = 1e-10;
// Sets the entries of Y (or of the `size` values y) below kJointErrorRoundingCutoff of the largest
// |entry| to exact zeros.
void ZeroJointErrorRoundingNoise(Eigen::MatrixXd* Y);
void ZeroJointErrorRoundingNoise(double* y, int size);
// The compliance and harmonics regressors' only entries that can be non-zero: y[k] = Y(joint of
// parameter k, k) (every other entry of Y is zero), rounding noise set to zero, without forming the
// num_joints x P matrix (what the solvers evaluate for every row). Compliance on the joint origins
// `origins` (one per joint) when not null, else on the model's.
void ComplianceRegressorValues(const RobotModel& model, const double* q, double* y,
                               const std::vector<SE3d>* origins = nullptr);
void HarmonicsRegressorValues(const RobotModel& model, const double* q, double* y);

// The joint offsets dq (num_joints) of every term the model carries, at commanded joints q, summed
// in registry order (each term's JointTermKind::AddOffsets; a geometry-dependent regressor such as
// compliance's is evaluated on model.joint_errors.regressor_origins when given).
void JointErrorOffsets(const RobotModel& model, const double* q, double* dq);
// q_eff = q + dq.
void EffectiveJoints(const RobotModel& model, const double* q, double* q_eff);

// ---- Gravity tilt (docs/joint_errors.md, "Gravity tilt").
//
// A base that is not level by a few tenths of a degree turns gravity by two small angles t about two
// unit axes u1, u2 perpendicular to the model's gravity g (GravityTiltAxes; for g along -z of the
// base: u1 = x, u2 = y):
//
//   g'(t) = exp([t1 u1 + t2 u2]^) g.
//
// Identifying t with the compliance products theta makes the compliance term bilinear:
// dq = Y(g'(t)) theta = sum_a g'_a(t) Y_a theta (ComplianceRegressorGravityAxes).

// u1, u2 (columns): u1 the base axis least aligned with g made perpendicular to it, u2 = u1 x g/|g|.
// Zero when g is zero.
Eigen::Matrix<double, 3, 2> GravityTiltAxes(const Eigen::Vector3d& gravity);

// g'(t) for double or ceres::Jet tilts.
template <typename T>
Vector3<T> TiltedGravity(const Eigen::Vector3d& gravity, const Eigen::Matrix<double, 3, 2>& axes,
                         const T* tilt) {
  const Vector3<T> w = axes.col(0).cast<T>() * tilt[0] + axes.col(1).cast<T>() * tilt[1];
  return ExpSO3(w) * gravity.cast<T>();
}
template <typename T>
Vector3<T> TiltedGravity(const Eigen::Vector3d& gravity, const T* tilt) {
  return TiltedGravity<T>(gravity, GravityTiltAxes(gravity), tilt);
}

// dg'/dt (3 x 2) at t, analytic (the right Jacobian of exp on SO(3)).
Eigen::Matrix<double, 3, 2> TiltedGravityJacobian(const Eigen::Vector3d& gravity,
                                                  const Eigen::Matrix<double, 3, 2>& axes,
                                                  const double* tilt);

// The tilt that turns `from` into the direction of `to` (the inverse of TiltedGravity on the
// directions, about from's axes), for reporting a simulated or stored tilt in the same angles.
Eigen::Vector2d GravityTiltBetween(const Eigen::Vector3d& from, const Eigen::Vector3d& to);

// The gravity tilt as a bilinear effect with the compliance term (lpoe/terms/bilinear_term.h):
// the weights are the tilted gravity, w(t) = g'(t), and Y_a the compliance regressor's gravity axes
// on a fixed reference model (the calibration's start model, as the compliance term's regressor).
class GravityTiltModel : public BilinearJointEffect {
 public:
  explicit GravityTiltModel(const RobotModel& reference);
  const RobotModel& reference() const { return reference_; }
  const Eigen::Vector3d& gravity() const { return reference_.gravity; }
  const Eigen::Matrix<double, 3, 2>& axes() const { return axes_; }
  // Y_a(q), a = x, y, z of the base (ComplianceRegressorGravityAxes on the reference).
  void AxisRegressors(const double* q, Eigen::MatrixXd Y[3]) const;
  // Their entries at their own joints (ComplianceValuesGravityAxes on the reference).
  void AxisValues(const double* q, double* const y[3]) const;
  Eigen::Vector3d Tilted(const double* tilt) const {
    return TiltedGravity<double>(gravity(), axes_, tilt);
  }

  // BilinearJointEffect: named "tilt", partner "compliance", two parameters (rad, "gravity.tilt1", "...2"),
  // three weights (g'(t), dg'/dt analytic).
  const char* name() const override { return kGravityTiltName; }
  const char* partner() const override;
  int num_parameters() const override { return 2; }
  std::string parameter_name(int i) const override;
  int num_weights() const override { return 3; }
  void Weights(const double* t, Eigen::VectorXd* dw, Eigen::MatrixXd* dw_dt) const override;
  // Z_a from Y_a's entries at their own joints only (the dense n x P product's zeros skipped).
  void RowRegressors(const Eigen::MatrixXd& basis, const double* q,
                     std::vector<Eigen::MatrixXd>* Z) const override;
  // The partner term rebuilt on the reference with the tilted gravity.
  Status PartnerAt(const JointTerm& partner, const double* t,
                   std::shared_ptr<const JointTerm>* out) const override;

 private:
  RobotModel reference_;
  Eigen::Matrix<double, 3, 2> axes_;
};

// dq = sum_a g_a Y_a theta (the compliance offsets for gravity g), for double or ceres::Jet.
template <typename T>
void ComplianceOffsets(const Eigen::MatrixXd Y_axes[3], const Vector3<T>& g, const T* theta,
                       T* dq) {
  const int n = static_cast<int>(Y_axes[0].rows());
  const int p = static_cast<int>(Y_axes[0].cols());
  for (int j = 0; j < n; ++j) {
    T sum = T(0);
    for (int c = 0; c < p; ++c) {
      const double y0 = Y_axes[0](j, c), y1 = Y_axes[1](j, c), y2 = Y_axes[2](j, c);
      if (y0 == 0 && y1 == 0 && y2 == 0) continue;
      sum += (g(0) * y0 + g(1) * y1 + g(2) * y2) * theta[c];
    }
    dq[j] = sum;
  }
}

// ---- Prediction with every term the model carries.

// FK(q_eff) * tool (mm, model frame).
Eigen::Vector3d PredictToolPosition(const RobotModel& model, const double* q, int tool);

// Predicted tool positions of `rows` configurations stored row-major in `q` (rows x num_joints,
// rad / mm). Row r measures tool `targets[r]` when `targets` is non-empty, else `tool`. Fails on
// wrong sizes, a tool index out of range or a non-finite joint value (messages name the row,
// 1-based).
Status PredictPositions(const RobotModel& model, const std::vector<double>& q,
                        const std::vector<int>& targets, int tool,
                        std::vector<Eigen::Vector3d>* positions);

// Joint values for prediction, CSV: a header naming q1..qN (any case) and optionally `target` (a tool
// name or 0-based index per row); other columns are ignored. '#' lines and blank lines are skipped;
// CRLF and a UTF-8 BOM are accepted. Revolute joints are converted from degrees when `degrees`.
// Fills `q` row-major and `targets` (empty when there is no target column). Errors read
// "<source>:<line>: <what>; expected <what>".
Status ParseJointsCsv(const std::string& text, const std::string& source, const RobotModel& model,
                      bool degrees, std::vector<double>* q, std::vector<int>* targets);
// "x,y,z" then one row per position, 17 significant digits.
std::string PositionsToCsv(const std::vector<Eigen::Vector3d>& positions);

// ---- Identifiable combinations.

// The combinations of one term that the data can see: theta = basis * x.
struct JointErrorReduction {
  std::string term;             // the registry name
  int num_full = 0;             // NumJointErrorParameters
  int rank_alone = 0;           // rank of the term's tool effect, geometry not considered
  Eigen::MatrixXd basis;        // num_full x r (r = basis.cols(), the identifiable combinations)
  std::vector<int> per_joint;   // identifiable combinations whose largest entry is in joint j's rows
  std::vector<double> singular_values;  // of the kept combinations (column-scaled tool effects)
};

// Relative singular-value threshold below which a combination counts as not identifiable.
constexpr double kJointErrorRankTolerance = 1e-7;

// For the terms named `terms` (in that order), the combinations whose effect on the measured tool
// positions at the rows of `data` (joint values and targets; positions are not used) lies outside
// the span of the geometric parameters of `geometric` and of the terms before them. Evaluated on
// `reference` (the registered start model). Each term's parameters are scaled by the norm of their
// tool effect before the singular value decomposition, so `basis` is in those units.
Status ReduceJointErrorTerms(const RobotModel& reference, const Parameterization& geometric,
                             const MeasurementSet& data, const std::vector<std::string>& terms,
                             std::vector<JointErrorReduction>* reductions);

// ---- Physical description (the simulator's truth; also a way to enter known stiffnesses).

struct JointErrorPhysics {
  std::vector<double> stiffness;  // per joint, N m/rad (N/mm prismatic); <= 0 or inf: rigid
  std::vector<double> link_mass;  // per link, kg
  std::vector<Eigen::Vector3d> link_com;  // per link, mm in link k's frame
  std::vector<Eigen::Vector4d> harmonics;  // per joint (a1, b1, a2, b2), rad; empty: none
  // The seed of the terms without a physical description here, which draw their truth values
  // themselves (each from its own stream; JointTermKind::Simulate).
  uint64_t seed = 11;
};

// The compliance products c_j (m_k, m_k com_k) and c_j of the physical description.
std::vector<double> CompliancePhysicsParameters(const JointErrorPhysics& physics);

}  // namespace lpoe

#endif  // LPOE_JOINT_ERRORS_H_
