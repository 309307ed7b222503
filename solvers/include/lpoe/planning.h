// Measurement planning: which joint configurations to measure so that the calibration identifies the
// model best (docs/planning.md).
//
// A pose q contributes the rows J(q) of the calibration's least-squares problem: the position
// Jacobian (eq. (29)) of every tool the tracker can see at q, in the identifiable parameterization.
// With isotropic measurement noise sigma the covariance of the identified parameters of a set of poses
// S is sigma^2 M(S)^-1, M(S) = sum_{q in S} J(q)^T J(q) (the information matrix). A plan is the set
// of N candidate poses that optimizes a scalar criterion of M:
//
//   D   maximize log det M                         (volume of the confidence ellipsoid)
//   A   minimize trace(M_s^-1)                     (sum of the scaled parameter variances)
//   E   maximize lambda_min(M_s)                   (the worst-determined scaled direction)
//   I   minimize trace(L M^-1)                     (average prediction variance of the tool position
//                                                   over a workspace sample, L = mean J_w^T J_w)
//   O1  (sigma_1 ... sigma_P)^(1/P) / sqrt(m)      (Borm and Menq; at fixed N a monotone function of
//                                                   det M: selects as D)
//   O3  sigma_min(J E)                             (Nahvi et al.; minimum singular value with the
//                                                   parameters scaled by their expected error E:
//                                                   1 mrad per rotation, 1 mm per translation)
//
// M_s = D M D is M with Jacobi column scaling (D from the candidate pool), m the number of rows. The
// selection is greedy (one pose at a time, the best gain) followed by an exchange (Fedorov / DETMAX):
// each planned pose is swapped for the best of a shortlist of candidates while the criterion improves.
// Rank-r updates of M^-1 (r = 3 x visible tools) keep a greedy step at one (rows x P x r) product,
// split over the cores by candidate.
#ifndef LPOE_PLANNING_H_
#define LPOE_PLANNING_H_

#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "lpoe/model/refusals.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/prior.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

enum class PlanCriterion { kD, kA, kE, kI, kO1, kO3 };

const char* PlanCriterionName(PlanCriterion criterion);
bool ParsePlanCriterion(const std::string& text, PlanCriterion* criterion);

// The parameters a plan identifies and the rows one pose contributes. This is the only place that
// decides the parameter blocks: the identifiable frame directions, then, when joint-space error
// terms (dq = Y(q) theta, joint_term.h) are given, one block per term with the columns
// J_q(q) Y(q) basis that the solvers use (measurement_model.h PredictPositionJacobian).
class PlanningModel {
 public:
  explicit PlanningModel(const RobotModel& model);
  // With joint-space error terms (built for `model`, in the order the calibration will use them):
  // each term keeps the combinations of its parameters that the configurations `reference`
  // (row-major, every tool measured at each; normally the feasible candidates) separate from the
  // geometry and from the earlier terms: the reduction both solvers make (with the linear solver's
  // default tolerance), so that a plan identifies what the calibration will solve.
  // `gravity_tilt`: the two tilt angles of the model's gravity (docs/joint_errors.md) join the
  // parameters after the terms' combinations, linearised at the model's own compliance values
  // (see PlanningGravityTiltStatus: the model must carry them and `terms` must hold "compliance").
  PlanningModel(const RobotModel& model, const std::vector<std::shared_ptr<const JointTerm>>& terms,
                const std::vector<double>& reference, bool gravity_tilt = false);
  PlanningModel(const PlanningModel&) = delete;
  PlanningModel& operator=(const PlanningModel&) = delete;

  const RobotModel& model() const { return model_; }
  const Parameterization& parameterization() const { return parameterization_; }
  int num_parameters() const { return parameterization_.num_parameters + num_tilt_parameters(); }
  // Of num_parameters(): the joint-space combinations (after the frame parameters), the gravity
  // tilt's two included (last).
  int num_joint_parameters() const {
    return parameterization_.num_joint_parameters() + num_tilt_parameters();
  }
  // 2 when the gravity tilt is planned for (the last two parameters), else 0.
  int num_tilt_parameters() const { return tilt_ ? tilt_->num_parameters() : 0; }

  // The position Jacobians (eq. (29), restricted to the identifiable directions, and the
  // joint-space columns J_q(q) Y(q) basis) of the listed tools at q, stacked: 3 rows per tool,
  // num_parameters() columns.
  void Rows(const double* q, const std::vector<int>& tools, Eigen::MatrixXd* J) const;

  // Expected parameter error magnitude of each parameter (O3's scaling): 1e-3 rad per unit of
  // rotation and 1 mm per unit of translation in its direction; for a joint-space combination the
  // value that moves the tools by 0.1 mm RMS over the reference configurations.
  Eigen::VectorXd ErrorScale() const;

 private:
  RobotModel model_;
  Parameterization parameterization_;
  BasisJacobian basis_;
  Eigen::VectorXd joint_error_scale_;  // ErrorScale of the joint-space combinations
  // The gravity tilt as a bilinear effect (lpoe/terms/bilinear_term.h), null when not planned for;
  // its columns at zero tilt and the partner's (compliance's) values in the model, every parameter
  // (identity basis).
  std::shared_ptr<const BilinearJointEffect> tilt_;
  Eigen::MatrixXd tilt_partner_basis_;
  Eigen::VectorXd tilt_partner_values_;
};

// Whether a plan can account for the gravity tilt (docs/planning.md, "Gravity tilt"). The tilt's
// columns are the change of the compliance offsets when gravity turns, d(dq)/dt = sum_a
// (dg/dt)_a Y_a(q) theta: proportional to the compliance values theta. A nominal model has none
// (they are what the calibration identifies), so its tilt information is zero and a plan cannot
// be chosen for it: an error that says so and what to do. A model that carries compliance values
// (a calibrated model's YAML, planning a recalibration) gives the tilt's information at those
// values. `terms` must include "compliance" (the tilt is identified with it).
Status PlanningGravityTiltStatus(const RobotModel& model,
                                 const std::vector<std::shared_ptr<const JointTerm>>& terms);

// ---- Constraints of the cell.

// The tracker and what it can see. Without a tracker every tool counts at every pose.
struct TrackerConstraint {
  bool enabled = false;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();  // in the model's base frame (mm)
  double max_range = std::numeric_limits<double>::infinity();  // mm
  // Half-angle of the cone around an SMR's facing direction within which the tracker sees it (rad).
  double acceptance_angle = 30.0 * 3.14159265358979323846 / 180.0;
  // Facing direction of each tool, in the tool's own frame (unit). Empty: +z of every tool frame.
  std::vector<Eigen::Vector3d> facing;
};

// The cell around the robot, in the model's base frame (mm). A pose is feasible when every joint
// origin after the first (the first does not move) and every tool point is at least min_z high and
// outside every keep-out box, and every tool point is inside `box` (when it is not empty).
struct CellConstraint {
  double min_z = -std::numeric_limits<double>::infinity();
  Eigen::AlignedBox3d box;  // empty (the default): no box
  std::vector<Eigen::AlignedBox3d> keep_out;

  bool enabled() const {
    return min_z > -std::numeric_limits<double>::infinity() || !box.isEmpty() || !keep_out.empty();
  }
};

// Whether the robot at q stays in the cell; when not and `why` is given, what is violated ("joint3
// origin at z = -120 mm, below --min_z", ...).
bool InsideCell(const RobotModel& model, const CellConstraint& cell, const double* q,
                std::string* why = nullptr);

// "xmin,ymin,zmin,xmax,ymax,zmax" (mm) -> a box; an error names what is wrong (six finite numbers,
// min <= max).
Status ParseBox(const std::string& text, Eigen::AlignedBox3d* box);

struct PlanConstraints {
  TrackerConstraint tracker;
  CellConstraint cell;
  // Poses whose singularity measure (see SingularityMeasure) is below this are not used.
  double min_singularity = 0.0;
};

// The tools the tracker sees at q: distance to the tracker at most max_range and the direction to
// the tracker within acceptance_angle of the tool's facing direction (R_0,tool facing). Occlusion by
// the robot's own links is not modelled.
std::vector<int> VisibleTools(const RobotModel& model, const TrackerConstraint& tracker,
                              const double* q);

// Distance from singular configurations: the smallest singular value of the geometric Jacobian of
// tool 0 (rotation rows, and translation rows divided by the arm's length scale CharacteristicLength),
// i.e. of min(6, n) singular values the last. 0 at a singular configuration; dimensionless.
double SingularityMeasure(const RobotModel& model, const double* q);
// Sum of the translations of the joint origins after the first and of tool 0 (mm).
double CharacteristicLength(const RobotModel& model);

// The sampling box of each joint: its limits; [-pi, pi] for a revolute joint without limits (one
// missing side: 2 pi from the other). A prismatic joint without both limits is an error.
Status JointRanges(const RobotModel& model, std::vector<double>* lower, std::vector<double>* upper);

// `count` configurations uniform in the joint ranges (row-major, n per row), seeded (portable).
Status SampleConfigurations(const RobotModel& model, int count, uint64_t seed,
                            std::vector<double>* q);

// ---- The candidate pool.

struct CandidatePool {
  int num_joints = 0;
  int num_parameters = 0;
  std::vector<double> q;            // feasible candidates, row-major
  std::vector<int> source;          // index of each candidate in the caller's list
  std::vector<std::vector<int>> visible;  // tools counted at each candidate
  Eigen::MatrixXd J;                // the stacked rows of every candidate
  std::vector<int> row_offset;      // candidate c has rows [row_offset[c], row_offset[c + 1])
  // Why candidates were dropped.
  int outside_limits = 0;
  int near_singular = 0;
  int nothing_visible = 0;
  int outside_cell = 0;  // PlanConstraints::cell

  int size() const { return static_cast<int>(source.size()); }
  int rows(int c) const { return row_offset[c + 1] - row_offset[c]; }
};

// Keeps the candidates (row-major `q`, n per row) that satisfy the joint limits and the constraints,
// and computes their rows.
CandidatePool BuildCandidatePool(const PlanningModel& pm, const std::vector<double>& q,
                                 const PlanConstraints& constraints);

// The pool and planning model for a calibration with joint-space terms (empty: the geometry only):
// the feasible candidates are found with the geometric model; the terms keep the combinations those
// candidates separate from the geometry (PlanningModel's reduction), and the pool's rows gain the
// terms' columns. Returns the planning model the pool's rows belong to.
// `gravity_tilt`: plan for the gravity tilt too (PlanningGravityTiltStatus must be ok).
std::unique_ptr<PlanningModel> BuildPlanningPool(
    const RobotModel& model, const std::vector<std::shared_ptr<const JointTerm>>& terms,
    const std::vector<double>& candidates, const PlanConstraints& constraints,
    CandidatePool* pool, bool gravity_tilt = false);

// L = mean over the workspace configurations (row-major) and every tool of J_w^T J_w: the predicted
// mean squared position error of the tools there is sigma^2 trace(L M^-1).
Eigen::MatrixXd WorkspaceMoment(const PlanningModel& pm, const std::vector<double>& workspace);

// ---- Evaluation of a plan.

struct PlanQuality {
  int num_poses = 0;
  int num_rows = 0;
  int rank = 0;
  double condition_number = std::numeric_limits<double>::infinity();  // column-scaled Jacobian
  // Expected RMS of the tool position error over the workspace after calibration, per unit of
  // measurement noise (mm per mm of per-axis sigma): sqrt(trace(L M^-1)). Infinite when M is singular.
  double predicted_rms = std::numeric_limits<double>::infinity();
  // The criteria's values (D: log det M_s; A: trace M_s^-1; E: lambda_min(M_s); I: trace(L M^-1);
  // O1, O3 as defined above). Infinite/-infinite where M is singular.
  double d = 0, a = 0, e = 0, i = 0, o1 = 0, o3 = 0;
};

// The information matrix of the listed candidates.
Eigen::MatrixXd Information(const CandidatePool& pool, const std::vector<int>& selected);

// With `prior_information` (PlanOptions::prior_information, not empty) the figures are the
// posterior's: M is the plan's information plus the prior's.
PlanQuality EvaluatePlan(const PlanningModel& pm, const CandidatePool& pool,
                         const std::vector<int>& selected, const Eigen::MatrixXd& workspace_moment,
                         const Eigen::MatrixXd& prior_information = Eigen::MatrixXd());

// A prior's information on `pm`'s parameters in the units of J^T J (sigma^2 times it, sigma the
// noise per axis of the data planned for): per frame B_f^T Lambda_f B_f (B_f the frame's
// identifiable directions), the base's registration directions free (FreeRegistrationDirections:
// the new data's tracker stands elsewhere); per joint-space term the prior lists (its P x P
// information Lambda_b) basis_b^T Lambda_b basis_b / scale^2 on the term's combinations, none on
// terms it does not list and on the gravity tilt.
Eigen::MatrixXd PlanningPriorInformation(const PlanningModel& pm, const ParameterPrior& prior,
                                         double sigma);

// The refusals of a plan, shared by lpoe_plan and lpoe.plan (lpoe/model/refusals.h): a plan of `count`
// poses must identify every parameter (rank) and have more rows than parameters (redundancy: with
// no more, it cannot check itself). The message says which and why.
inline Status PlanRefusal(const PlanQuality& quality, int parameters, int count) {
  const std::string what = "the plan of " + std::to_string(count) + " pose" +
                           (count == 1 ? "" : "s");
  if (Status s = CheckFullRank(quality.rank, parameters, what); !s.ok()) return s;
  return CheckRedundancy(quality.num_rows, parameters, what);
}

// ---- Selection.

struct PlanOptions {
  PlanCriterion criterion = PlanCriterion::kD;
  int max_exchange_passes = 4;  // passes over the plan; stops early at a pass without improvement
  int shortlist = 64;           // candidates tried per exchange (the largest variances d(c))
  // Threads for the per-candidate updates (0: one per hardware thread). The plan does not depend
  // on it: every candidate's terms are computed alone, in fixed chunks.
  int num_threads = 0;
  // A prior's information on the planning parameters (docs/recalibration.md, lpoe_plan --prior),
  // in the units of J^T J: sigma^2 times the prior's information, sigma the new data's noise per
  // axis (PlanningPriorInformation). The plan maximizes the criterion of M + this (the posterior),
  // so its poses go where the prior is weak. Empty: none.
  Eigen::MatrixXd prior_information;
};

struct PlanResult {
  std::vector<int> selected;  // candidate indices in the pool
  int exchanges = 0;          // accepted swaps
  int passes = 0;
};

// Chooses `count` distinct candidates of the pool. Fails when the pool has fewer than `count`.
// `workspace_moment` is used by criterion I.
Status SelectPlan(const PlanningModel& pm, const CandidatePool& pool, int count,
                  const Eigen::MatrixXd& workspace_moment, const PlanOptions& options,
                  PlanResult* result);

// `count` distinct candidates drawn at random (seeded): the baseline a plan is compared against.
std::vector<int> RandomPlan(int pool_size, int count, uint64_t seed);

// ---- What the model cannot explain (docs/planning.md, "Unmodelled error").
//
// The measured error of a real arm has a part no parameter of the calibration describes. It is
// modelled as a random field u(q, tool) (mm per axis) with variance s^2 and correlation
// exp(-1/2 sum_j ((q_j - q'_j) / l_j)^2) (same tool ? 1 : rho) between poses: the residual layer's
// kernel. A least-squares calibration of the plan S fits it where it measured: with
// A = M^-1 and the plan's rows J_S, x_hat - x = A J_S^T (u_S + noise), and the tools' positions
// over the workspace W are off by J_w (x_hat - x) - u_w. The expected mean square over the
// workspace and the tools is
//
//   sigma^2 trace(L A) + s^2 (trace(L A H A) - 2 trace(A G) + 3),
//   H = J_S^T C_SS J_S,  G = J_S^T R_S,  R_c = mean over (w, t) of C_{c,wt} J_wt
//
// (C the correlations of u between rows): the noise's part, the unmodelled error's bias on the
// calibration and what it leaves at the workspace. With s = 0 it is the I criterion's figure.
struct UnmodelledErrorModel {
  double std = 0;                 // s, mm per axis; 0: none
  Eigen::VectorXd length_scales;  // l_j per joint (rad / mm)
  double tool_correlation = 1;    // rho
};

// A plan's predicted RMS error of the calibrated tool positions over the workspace (mm; calibrated
// minus true, the true including the unmodelled error; the held-out measurement's own noise not
// counted).
struct PlanErrorPrediction {
  double noise_rms = std::numeric_limits<double>::infinity();       // sigma sqrt(trace(L A))
  double unmodelled_rms = std::numeric_limits<double>::infinity();  // the s^2 part's root
  double total_rms = std::numeric_limits<double>::infinity();       // root of the sum of squares
};

// The prediction above for plans from one pool, and an exchange that lowers it.
class UnmodelledPlanning {
 public:
  // `workspace` row-major (its first `max_workspace` configurations enter R), `L` the workspace
  // moment of the same planning model, `sigma` the noise (mm per axis).
  UnmodelledPlanning(const PlanningModel& pm, const CandidatePool& pool,
                     const std::vector<double>& workspace, const Eigen::MatrixXd& L,
                     const UnmodelledErrorModel& unmodelled, double sigma,
                     int max_workspace = 500);

  PlanErrorPrediction Predict(const std::vector<int>& selected) const;

  // One-for-one swaps of plan members for candidates (per member a seeded shortlist of
  // `shortlist` candidates outside the plan) while the predicted total decreases; at most
  // `max_passes` passes over the plan. Returns the number of swaps made.
  int Exchange(std::vector<int>* selected, int max_passes, int shortlist, uint64_t seed) const;

 private:
  // The matrices of one evaluation of the total and of one candidate's rows, kept between
  // evaluations (one per thread; planning_unmodelled.cc).
  struct Scratch;
  Scratch NewScratch() const;
  // Correlation of u between candidates a and b (pose part; tools by `tool_factor`).
  double PoseCorrelation(const double* qa, const double* qb) const;
  // C_{a,b} J_b for candidate rows a (tools of a) and b, written to the first rows_a rows of
  // `out` (P columns); false (and `out` untouched) when the poses are uncorrelated (C = 0).
  bool CorrelatedRows(int a, int b, Eigen::MatrixXd* out) const;
  double Total(const Eigen::MatrixXd& M, const Eigen::MatrixXd& H, const Eigen::MatrixXd& G,
               Scratch* scratch, PlanErrorPrediction* out) const;

  const CandidatePool& pool_;
  Eigen::MatrixXd L_;
  UnmodelledErrorModel u_;
  double sigma2_ = 0, s2_ = 0;
  Eigen::VectorXd inv_l_;
  Eigen::MatrixXd R_;  // pool rows x P (like pool.J)
};

}  // namespace lpoe

#endif  // LPOE_PLANNING_H_
