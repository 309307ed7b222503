// The calibration problem as building blocks another estimator can extend (docs/problem_builder.md).
//
// CalibrationProblem owns the parameter blocks of a calibration of `nominal` on `data`:
//   * one block per local frame that the data determine (every joint frame, and the tools some row
//     measures), 7 numbers [qx qy qz qw tx ty tz] with an Se3Manifold (right perturbation, eq. (19),
//     restricted to the frame's basis of the parameterization);
//   * one block per joint-space term that keeps identifiable combinations (joint_term.h), k_b
//     numbers x_b, theta_b = basis_b x_b, starting at zero (or options' initial values);
//   * one block per effect of options.bilinear_effects (lpoe/terms/bilinear_term.h; the gravity
//     tilt: 2 numbers, rad).
// one list (blocks()), each block of a kind of the block-kind registry
// (solvers/src/calibration/block_kind.h), which supplies its manifold, step and columns;
// and offers three ways in:
//   (a) AddTo(problem): adds those blocks and one residual block per measurement
//         position data: r = (P_model(q) - P_measured) / sigma                       (eq. (29))
//         pose data:     r = diag(w,w,w,1,1,1) log(T_measured T_model^-1) / sigma       (eq. (17))
//       (optionally under a robust loss) to a caller-owned ceres::Problem, and returns the residual
//       block ids; the caller adds its own residuals and priors on frame_block(f) / joint_block(b),
//       sets blocks constant, solves, and reads the solution back with Model() and JointTerms().
//       CalibrateCeres (ceres_solver.h) is exactly this plus the identifiability check, a history
//       callback and the covariance.
//   (b) NormalEquations(): the linearized problem at the blocks' current values as normal equations
//       H = J^T W J, g = J^T W y (W = I / sigma^2, y = measured - predicted), with the parameters'
//       names: the same matrices as CalibrateLinear's (scaled by 1 / sigma^2), to add to the
//       caller's own; Update(x) applies a step x (e.g. the Gauss-Newton step H^-1 g) to the blocks.
//   (c) Analyze() (identifiability from the normal equations: rank, condition number, the
//       directions no data can determine) and Covariance(problem) (ceres::Covariance on the
//       caller's problem, including the caller's residuals).
#ifndef LPOE_PROBLEM_BUILDER_H_
#define LPOE_PROBLEM_BUILDER_H_

#include <array>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <ceres/problem.h>

#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/measurements/measurements.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/prior.h"
#include "lpoe/problem_options.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/se3_manifold.h"
#include "lpoe/status.h"

namespace lpoe {

namespace internal {
class BlockKind;  // solvers/src/calibration/block_kind.h
struct JointSpaceRegressors;  // solvers/src/linearization/normal_equations.h
struct NormalEquations;
struct NormalEquationsOptions;
struct ProblemSetup;  // solvers/src/calibration/problem_setup.h
}  // namespace internal

// The problem's decisions and its cost are the bases' (problem_options.h), shared with the solvers'
// options: a solver passes its share by assigning the base. The prior is resolved once with the
// other decisions (its reference the nominal model unless it has one); the problem adds no
// residuals for it: the caller does (CalibrateCeres).
struct CalibrationProblemOptions : ProblemCostOptions {
  // Rows per residual block of AddTo(). 1: one block per row. More: position data without a loss
  // and without joint terms go in blocks of this many consecutive rows (the last one shorter), each
  // with the analytic Jacobian of the measurement model over all solved frames; otherwise one
  // block per row all the same (a robust loss must see each row's residual: Ceres applies it to a
  // block's whole squared norm).
  int rows_per_block = 1;
};

// User errors in the options: names of the loss, ranges.
Status ValidateCalibrationProblemOptions(const CalibrationProblemOptions& options);
// User errors in the options or the data: names of the loss, ranges, pose data without
// orientations, measurements that do not fit the model.
Status ValidateCalibrationProblem(const RobotModel& nominal, const MeasurementSet& data,
                                  const CalibrationProblemOptions& options);

// Normal equations of the solved parameters (see (b) above).
struct ProblemNormalEquations {
  Eigen::MatrixXd H;  // J^T W J, num_parameters square
  Eigen::VectorXd g;  // J^T W y
  double cost = 0;    // 0.5 y^T W y (Ceres's cost without a robust loss)
  // The solved parameters in column order (frames in model order, then joint-term blocks): the
  // parameterization with unmeasured tools left out. names[k] == parameterization.parameters[k].name.
  Parameterization parameterization;
  std::vector<std::string> names;
  bool finite = true;  // false when a residual or a Jacobian entry is not finite
};

// Identifiability of the solved parameters by the data at the blocks' current values.
struct ProblemAnalysis {
  int num_parameters = 0;  // identifiable parameters to determine (the gauge of `full` excluded)
  long num_equations = 0;  // residual rows
  int rank = 0;            // of the column-scaled Jacobian
  double condition_number = 0;
  Eigen::VectorXd singular_values;         // column-scaled Jacobian, descending
  std::vector<std::string> parameter_names;  // the identifiable directions analysed, in order
  Eigen::MatrixXd normal_matrix;           // J^T J (unweighted) of those directions
  // Directions no data can determine (gauge of the frames, left-out joint-term combinations,
  // never-measured tools), each with its reason.
  std::vector<Direction> unidentifiable;
  // The (up to three) parameters carrying most of the weakest direction.
  std::string weakest;
  bool finite = true;
  // Enough equations, full rank and condition number <= the limit given to Analyze().
  bool identifiable = false;
  std::string message;  // why not (the solvers' message); empty when identifiable
};

// One parameter block of a CalibrationProblem: a local frame (7 numbers, Se3Manifold), a
// joint-space term's coordinates (k_b numbers) or a bilinear effect's (the gravity tilt: 2 numbers),
// each of one kind of the block-kind registry (solvers/src/calibration/block_kind.h), which
// supplies its manifold, its step, where its values go and its columns.
struct ProblemBlock {
  const internal::BlockKind* kind = nullptr;
  int index = 0;          // the kind's own index: frame f, joint block b, bilinear block b
  int offset = 0;         // first parameter in parameterization()'s numbering
  int solved_offset = 0;  // first parameter in SolvedParameterization()'s (NormalEquations, Update)
  int tangent_size = 0;
  std::vector<double> values;   // the block Ceres sees (ambient numbers)
  std::vector<double> initial;  // its values at construction
};

class CalibrationProblem {
 public:
  using FrameBlock = std::array<double, kSe3AmbientSize>;

  // `data` must outlive the object (its rows are read by NormalEquations, Analyze and AddTo);
  // `nominal` is copied. The options must pass ValidateCalibrationProblem (CHECKed). The joint-term
  // reduction (a pass over the data) happens here.
  CalibrationProblem(const RobotModel& nominal, const MeasurementSet& data,
                     const CalibrationProblemOptions& options);
  // A problem on decisions already made (internal, problem_setup.h): `setup` is
  // internal::SetUpProblem's on these data with the options' request (the linear solver's, whose
  // options are checked by its own rules); the options are not validated again.
  CalibrationProblem(const RobotModel& nominal, const MeasurementSet& data,
                     const CalibrationProblemOptions& options,
                     std::shared_ptr<const internal::ProblemSetup> setup);
  CalibrationProblem(const CalibrationProblem&) = delete;
  CalibrationProblem& operator=(const CalibrationProblem&) = delete;

  const CalibrationProblemOptions& options() const { return options_; }
  const RobotModel& nominal() const { return nominal_; }
  const MeasurementSet& data() const { return *data_; }
  // Every frame's basis and every joint block (unmeasured tools included, with their basis).
  const Parameterization& parameterization() const { return parameterization_; }

  // Frame f (joints 0..n-1, then tools) is solved: a joint, or a tool some row measures.
  bool frame_solved(int f) const { return frame_blocks_[f] >= 0; }
  // The parameter block of frame f (7 numbers), nullptr when the frame is not solved.
  double* frame_block(int f);
  // The parameter block of joint-space term b (k_b numbers), nullptr when it keeps no combination.
  double* joint_block(int b);
  // The block of parameterization().bilinear_blocks[b] (options().bilinear_effects: the gravity
  // tilt's 2 numbers, rad), nullptr without it (see block_status()).
  double* bilinear_block(int b = 0);
  // Why an effect of options().bilinear_effects could not be added (no identified combination of
  // its partner); ok otherwise.
  const Status& block_status() const { return block_status_; }
  // Every block, in the registry's order of kinds (solved frames in model order, then joint
  // blocks, then the bilinear blocks): the covariance order, and the order of the columns of NormalEquations().
  const std::vector<ProblemBlock>& blocks() const { return blocks_; }
  // Every solved block's values in blocks() order.
  std::vector<double*> parameter_blocks();
  // Tangent size of each block of parameter_blocks(), and its first parameter in
  // parameterization()'s numbering.
  std::vector<int> tangent_sizes() const;
  std::vector<int> tangent_offsets() const;

  // (a) Adds the solved blocks (with their manifolds) and one residual block per row to `problem`
  // (per options().rows_per_block rows when batched, see BatchedRows()), whose options must take
  // ownership of cost functions, loss functions and manifolds (Ceres's default). Returns the
  // residual block ids, in row order. Call once per problem.
  std::vector<ceres::ResidualBlockId> AddTo(ceres::Problem* problem);
  // Rows per residual block AddTo() uses: options().rows_per_block when the rows can be batched
  // (position data, no loss, no joint-term block), else 1.
  int BatchedRows() const;

  // The model at the blocks' current values: `nominal` with the solved frames replaced (a block
  // still holding its initial value keeps the nominal frame exactly).
  RobotModel Model() const;
  // The joint-space terms' values theta_b = basis_b x_b (options().joint_terms order).
  std::vector<JointTermValues> JointTerms() const;
  // The joint blocks' coordinates, concatenated, then the bilinear blocks' (num_joint_parameters()).
  Eigen::VectorXd JointState() const;
  // The joint values the chain is evaluated at for every row (rows x n, row-major): data().q
  // shifted by the joint-space terms at their current values, q + sum_b Y_b(q) theta_b (as
  // WithEffectiveJointValues(JointTerms(), data())); data().q without terms. From the reduction's
  // stored slots (n + 89 multiply-adds a row on cobot6) when it has them.
  std::vector<double> EffectiveJointValues() const;

  // The solved parameters (unmeasured tools left out): the numbering of NormalEquations() and
  // Update().
  const Parameterization& SolvedParameterization() const;
  // Every decision of the problem (internal, problem_setup.h): the parameterization, the frames
  // solved, the structure reference, the prior; the same function makes CalibrateLinear's.
  const internal::ProblemSetup& setup() const { return *setup_; }

  // (b) Normal equations at the current values (W = I / sigma^2).
  ProblemNormalEquations NormalEquations() const;
  // Applies x (ProblemNormalEquations::parameterization's numbering): T_f <- T_f exp((B_f x_f)^)
  // (eq. (19)) for each solved frame, x_b added to each joint block.
  void Update(const Eigen::VectorXd& x);

  // The linear solver's access (linear_solver.cc, a Gauss-Newton loop over this problem; internal:
  // normal_equations.h). The linearization at the current values in SolvedParameterization()'s
  // numbering, unweighted (W = I; NormalEquations() is this times 1 / sigma^2), assembled as `o`
  // asks (stacked rows, cached joint rows, the rows' errors, frozen joint blocks); the measurement
  // fields (orientation, its weight) are the problem's, and the joint regressors the reduction's
  // unless `o` gives its own.
  internal::NormalEquations Linearize(const internal::NormalEquationsOptions& o) const;
  // The blocks' values (and the model they stand for), to go back to after a trial step.
  struct Values {
    std::vector<std::vector<double>> blocks;  // each block's values, in blocks() order
    RobotModel model;
    std::vector<std::vector<double>> model_values;
  };
  Values values() const;
  void SetValues(const Values& v);
  // Every frame of the model to `model`'s (a solution found elsewhere: the linear solver's warm
  // start on a subsample); the joint blocks are kept.
  void SetFrames(const RobotModel& model);

  // (c) Identifiability at the current values (for the full parameterization: in the identifiable
  // basis, whose rank is what the data can determine). `max_condition_number` as the solvers'.
  ProblemAnalysis Analyze(double max_condition_number = 1e8) const;
  // The same check on the caller's normal matrix `H` of the solved parameters at the current values
  // (SolvedParameterization()'s numbering, e.g. with a prior's information added: the linear
  // solver's; for the full parameterization H is not used, its identifiable basis is linearized).
  // The eigenvalues decide; the weakest direction (eigenvectors) is computed only for a refusal's
  // message. With too few equations the rank is still computed (an informative prior may make up
  // for them: the caller decides).
  ProblemAnalysis AnalyzeNormalMatrix(const Eigen::MatrixXd& H,
                                      double max_condition_number = 1e8) const;

  // Covariance of the solved parameters from ceres::Covariance (DENSE_SVD; pseudo-inverse for the
  // full parameterization) on `problem` (which may carry the caller's residuals, priors and
  // constant blocks), in parameterization()'s numbering (num_parameters square; unsolved tools'
  // rows and columns zero), in the residuals' units (a priori: scale by s^2 for a posteriori).
  // An error when ceres::Covariance::Compute() fails (rank-deficient Jacobian).
  // `null_space_rank` (full parameterization): the number of smallest eigenvalues dropped, i.e. the
  // pseudo-inverse truncated to the identifiable rank, as the solvers' steps are (a structurally
  // lost direction can come back weakly through the gauge once the model moved, and would
  // otherwise get a huge variance); -1: Ceres's rule (eigenvalues below
  // min_reciprocal_condition_number of the largest are dropped).
  Status Covariance(ceres::Problem* problem, int num_threads, Eigen::MatrixXd* covariance,
                    int null_space_rank = -1);
  // The same covariance from NormalEquations() (H^-1; full: the same pseudo-inverse), for a
  // problem of this builder's residuals alone without a robust loss: no Jacobian of all rows is
  // formed (10^6 rows) and no SVD of it. An error, as Compute()'s, when the column-scaled Jacobian's
  // reciprocal condition number is below ceres::Covariance::Options's
  // min_reciprocal_condition_number (or H is not positive definite).
  Status NormalEquationsCovariance(Eigen::MatrixXd* covariance, int null_space_rank = -1) const;

 private:
  // C (parameter_blocks() order) in parameterization()'s numbering.
  Eigen::MatrixXd ScatterCovariance(const Eigen::MatrixXd& C) const;
  // Analyze() and AnalyzeNormalMatrix(): `H_solved` null, formed here.
  ProblemAnalysis AnalyzeWith(const Eigen::MatrixXd* H_solved, double max_condition_number) const;

  RobotModel nominal_;
  const MeasurementSet* data_;
  CalibrationProblemOptions options_;
  std::shared_ptr<const internal::ProblemSetup> setup_;
  Parameterization parameterization_;
  std::vector<ProblemBlock> blocks_;  // built once: the values' addresses are Ceres's blocks
  std::vector<int> frame_blocks_;     // frame f's index in blocks_, -1 when not solved
  std::vector<int> joint_blocks_;     // joint block b's, -1 when it keeps no combination
  std::vector<int> bilinear_blocks_;  // bilinear block b's index in blocks_
  // The model the blocks' values stand for, exactly (the steps of Update() applied to the frames'
  // matrices, no quaternion round trip), and the values it was written as: Model() takes a frame
  // from it while its block still holds those values (the nominal model and the initial values
  // until Update() or SetFrames()).
  RobotModel current_;
  std::vector<std::vector<double>> current_values_;
  Status block_status_;
  // With joint-space terms, the reduction's by-products (setup_'s): the rows' regressors (slot
  // basis of parameterization_'s blocks) and the normal equations at the nominal values with every
  // term whole, in setup_->analysed_parameterization.
  std::shared_ptr<internal::JointSpaceRegressors> regressors_;
  std::shared_ptr<internal::NormalEquations> analysed_;
};

}  // namespace lpoe

#endif  // LPOE_PROBLEM_BUILDER_H_
