#include "lpoe/ceres_solver.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <sstream>
#include <utility>
#include <vector>

#include <ceres/ceres.h>
#include <glog/logging.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "calibration/block_kind.h"
#include "identifiability/identifiability.h"
#include "lpoe/kinematics/eigen_decompositions.h"
#include "calibration/prior_terms.h"
#include "calibration/problem_setup.h"
#include "calibration/solve_on_problem.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "lpoe/problem_builder.h"
#include "lpoe/model/statistics.h"

namespace lpoe {
namespace {

bool ParseLinearSolver(const std::string& name, ceres::LinearSolverType* type) {
  if (name == "auto") {
    *type = ceres::DENSE_QR;
    return true;
  }
  return ceres::StringToLinearSolverType(name, type);
}

}  // namespace

namespace internal {

CalibrationProblemOptions CeresProblemOptions(const CeresSolverOptions& options, int rows) {
  CalibrationProblemOptions o;
  static_cast<ProblemCostOptions&>(o) = options;  // the decisions, sigma and the loss
  o.rows_per_block = options.rows_per_block > 0                   ? options.rows_per_block
                     : rows >= CeresSolverOptions::kBatchFromRows ? 1024
                                                                   : 1;
  return o;
}

}  // namespace internal

namespace {

// The stopping rules of convergence.h on Ceres's accepted steps: the step is the difference of the
// models before and after it in the solved directions, the standard deviations come from J^T J at
// the start (`H`, solved columns only; empty: unknown) and the current cost.
//
// The full parameterization solves the frames' gauge directions too (Levenberg-Marquardt's damping
// keeps the rank-deficient steps finite). Its step is measured after projecting it onto the
// identifiable directions at the start (`projector`), and its standard deviations are those of the
// pseudo-inverse truncated to the identifiable rank (`unit_sd`, for s = 1): what the linear solver's
// truncated pseudo-inverse solves. Otherwise a structurally lost direction (a tool on the last
// joint's axis: the axis' tilt about the tool), null at the start but weakly curved once the model
// moves through the gauge, lets LM drift along it with no change of the cost, and no rule fired.
struct ConvergenceWatch {
  ConvergenceOptions options;
  const Parameterization* p = nullptr;
  std::vector<int> columns;  // solved parameters (used frames) in p's order
  Eigen::MatrixXd H;
  Eigen::MatrixXd projector;  // full parameterization: onto the identifiable directions
  Eigen::VectorXd unit_sd;    // full parameterization: standard deviations at s = 1
  std::vector<int> moved;     // full parameterization: the entries of unit_sd that are not zero
  int small_drops = 0;        // full parameterization: consecutive steps that changed nothing
  static constexpr int kCrawlSteps = 10;
  std::vector<double> recent_drops;  // full parameterization: chi^2 drops of the last steps
  long dof = 0;
  ConvergenceDecision decision;

  bool Stop(const RobotModel& before, const RobotModel& after, double cost, double previous_cost) {
    const Eigen::VectorXd all = ParameterDifference(*p, before, after);
    ConvergenceState state;
    state.step.resize(static_cast<Eigen::Index>(columns.size()));
    for (size_t k = 0; k < columns.size(); ++k) state.step(k) = all(columns[k]);
    if (H.size() > 0) state.standard_deviation = StandardDeviations(H, cost, dof);
    if (projector.size() > 0) {
      // The parameters the identifiable directions move (a pure gauge parameter, e.g. a tool
      // orientation with position data, has neither step nor variance there).
      const Eigen::VectorXd projected = projector * state.step;
      const double s = dof > 0 ? std::sqrt(2.0 * cost / dof) : 0.0;
      state.step.resize(static_cast<Eigen::Index>(moved.size()));
      state.standard_deviation.resize(static_cast<Eigen::Index>(moved.size()));
      for (size_t k = 0; k < moved.size(); ++k) {
        state.step(k) = projected(moved[k]);
        state.standard_deviation(k) = s * unit_sd(moved[k]);
      }
    }
    state.parameter_scale = ParameterScale(after);
    state.cost = cost;
    state.previous_cost = previous_cost;
    decision = TestConvergence(options, state);
    if (projector.size() > 0 && !decision.converged() && dof > 0 && previous_cost > 0 &&
        cost > 0) {
      // Full parameterization: LM can also crawl along a weakly curved valley that the projection
      // at the start does not separate (a registered start: the lost direction is then not exactly
      // null), a fraction of a standard deviation per step at a cost change of 1e-8. A step that
      // lowers chi^2 = 2 cost / s^2 by less than sd_fraction^2 (a Gauss-Newton step of
      // sd_fraction standard deviations in the Mahalanobis norm would lower it by about that) is
      // statistically nothing; two in a row end the iterations.
      const double chi2_drop = (previous_cost - cost) * static_cast<double>(dof) / cost;
      const double limit = options.sd_fraction * options.sd_fraction;
      small_drops = chi2_drop <= limit ? small_drops + 1 : 0;
      // A steadier crawl (each step a hundredth of a standard deviation along the valley of a
      // tool exactly on the last axis, chi^2 falling by 2e-3 a step) passes that test for ever:
      // kCrawlSteps steps in a row that together lower chi^2 by at most kCrawlSteps * sd_fraction
      // (a tenth of a unit: no parameter moves by a meaningful fraction of its deviation) end it.
      recent_drops.push_back(chi2_drop);
      if (static_cast<int>(recent_drops.size()) > kCrawlSteps) recent_drops.erase(recent_drops.begin());
      double window = 0;
      for (double d : recent_drops) window += d;
      const bool crawl = static_cast<int>(recent_drops.size()) == kCrawlSteps &&
                         window <= kCrawlSteps * options.sd_fraction;
      if (small_drops >= 2 || crawl) {
        char buf[256];
        if (crawl) {
          std::snprintf(buf, sizeof(buf),
                        "converged: the last %d steps lowered chi^2 by %.3g in all (tolerance "
                        "%.3g; |x| = %.3g)",
                        kCrawlSteps, window, kCrawlSteps * options.sd_fraction,
                        decision.step_norm);
        } else {
          std::snprintf(buf, sizeof(buf),
                        "converged: the last two steps lowered chi^2 by at most %.3g (tolerance "
                        "%.3g, sd_fraction squared; |x| = %.3g)",
                        chi2_drop, limit, decision.step_norm);
        }
        decision.rule = StopRule::kCost;
        decision.message = buf;
      }
    }
    return decision.converged();
  }
};

// Records the history (IterationRecord per accepted step) with the state of the blocks, which Ceres
// updates every iteration (update_state_every_iteration).
class HistoryCallback : public ceres::IterationCallback {
 public:
  HistoryCallback(const CalibrationProblem& problem, double cost_scale,
                  std::vector<IterationRecord>* history,
                  std::function<void(const IterationRecord&)> on_iteration,
                  ConvergenceWatch* watch)
      : watch_(watch),
        previous_(problem.nominal()),
        problem_(problem),
        cost_scale_(cost_scale),
        history_(history),
        on_iteration_(std::move(on_iteration)) {}

  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override {
    if (summary.iteration > 0 && !summary.step_is_successful) return ceres::SOLVER_CONTINUE;
    RobotModel model = problem_.Model();
    IterationRecord r;
    r.iteration = summary.iteration;
    r.cost = summary.cost * cost_scale_;
    const std::vector<double> q = problem_.EffectiveJointValues();
    const AxisStatistics norm = PositionErrorNormMoments(model, problem_.data(), q.data());
    r.max_error = norm.max_abs;
    r.mean_error = norm.mean_abs;
    r.step_norm = summary.iteration > 0 ? summary.step_norm : 0.0;
    const double previous_cost = history_->empty() ? -1.0 : history_->back().cost;
    history_->push_back(r);
    if (on_iteration_) on_iteration_(r);
    if (summary.iteration > 0 && watch_->Stop(previous_, model, r.cost, previous_cost)) {
      return ceres::SOLVER_TERMINATE_SUCCESSFULLY;
    }
    previous_ = std::move(model);
    return ceres::SOLVER_CONTINUE;
  }

 private:
  ConvergenceWatch* watch_;
  RobotModel previous_;
  const CalibrationProblem& problem_;
  double cost_scale_;
  std::vector<IterationRecord>* history_;
  std::function<void(const IterationRecord&)> on_iteration_;
};

// The covariance C in `all`'s numbering (every tool) restricted to the solved parameters (all
// with unmeasured tools left out, LeaveOutUnmeasuredTools): each of the problem's blocks, whatever
// its kind, from its offset in `all` to its offset in the solved numbering.
Eigen::MatrixXd SolvedCovariance(const CalibrationProblem& builder, const Eigen::MatrixXd& C) {
  const int P = builder.SolvedParameterization().num_parameters;
  std::vector<int> index(P);
  for (const ProblemBlock& b : builder.blocks()) {
    for (int c = 0; c < b.tangent_size; ++c) index[b.solved_offset + c] = b.offset + c;
  }
  Eigen::MatrixXd out(P, P);
  for (int i = 0; i < P; ++i) {
    for (int j = 0; j < P; ++j) out(i, j) = C(index[i], index[j]);
  }
  return out;
}

// The full parameterization's projector and truncated standard deviations (see ConvergenceWatch)
// from the normal equations at the start: the frames' block (the joint-space blocks eliminated by
// their Schur complement), column-scaled, its `rank` largest eigenpairs less the joint-space ones.
void FullParameterizationWatch(const CalibrationProblem& builder, double sigma, int rank,
                               ConvergenceWatch* watch) {
  const ProblemNormalEquations ne = builder.NormalEquations();
  const int F = static_cast<int>(watch->columns.size());
  const int S = static_cast<int>(ne.H.rows());
  if (!ne.finite || S < F || F == 0) return;
  Eigen::MatrixXd H = sigma * sigma * ne.H;  // J^T J, unweighted
  Eigen::MatrixXd Hf = H.topLeftCorner(F, F);
  if (S > F) {
    Eigen::LLT<Eigen::MatrixXd> llt(H.bottomRightCorner(S - F, S - F));
    if (llt.info() != Eigen::Success) return;
    Hf -= H.topRightCorner(F, S - F) * llt.solve(H.bottomLeftCorner(S - F, F));
  }
  const int r = std::min(F, rank - (S - F));
  if (r <= 0) return;
  const Eigen::VectorXd d = internal::ColumnScale(Hf);
  const Eigen::MatrixXd Hs = d.asDiagonal() * Hf * d.asDiagonal();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(Hs);
  if (eig.info() != Eigen::Success || !(eig.eigenvalues()(F - r) > 0)) return;
  const Eigen::MatrixXd V = eig.eigenvectors().rightCols(r);  // the largest r
  const Eigen::VectorXd inv_l = eig.eigenvalues().tail(r).cwiseInverse();
  watch->projector = d.asDiagonal() * V * V.transpose() * d.cwiseInverse().asDiagonal();
  const Eigen::MatrixXd C = d.asDiagonal() * V * inv_l.asDiagonal() * V.transpose() * d.asDiagonal();
  watch->unit_sd = C.diagonal().cwiseMax(0.0).cwiseSqrt();
  const double largest = watch->unit_sd.maxCoeff();
  for (int k = 0; k < F; ++k) {
    if (watch->unit_sd(k) > 1e-12 * largest) watch->moved.push_back(k);
  }
}

// The prior's residual of one frame (prior_terms.h): weight * L log(T_ref^-1 T) on the frame's
// 7-number block; `weight` = s / sigma (the data's standard deviation over the residuals'), read at
// every evaluation so that the solve can be repeated with another s.
struct FramePriorResidual {
  FramePriorResidual(const SE3d& reference, const Matrix6d& L, const double* weight)
      : reference_inverse(reference.Inverse()), L(L), weight(weight) {}
  template <typename T>
  bool operator()(const T* x, T* residual) const {
    const SE3<T> D = reference_inverse.cast<T>() * Se3FromArray(x);
    const Vector6<T> xi = LogSE3(D);
    for (int i = 0; i < 6; ++i) {
      T sum = T(0);
      for (int j = 0; j < 6; ++j) sum += T(L(i, j)) * xi(j);
      residual[i] = T(*weight) * sum;
    }
    return true;
  }
  SE3d reference_inverse;
  Matrix6d L;
  const double* weight;
};

// The prior's residual of one joint block: weight * (M x - c), M = L_b basis_b, c = L_b theta_ref.
class JointPriorResidual : public ceres::CostFunction {
 public:
  JointPriorResidual(Eigen::MatrixXd M, Eigen::VectorXd c, const double* weight)
      : M_(std::move(M)), c_(std::move(c)), weight_(weight) {
    set_num_residuals(static_cast<int>(M_.rows()));
    mutable_parameter_block_sizes()->push_back(static_cast<int>(M_.cols()));
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const Eigen::Map<const Eigen::VectorXd> x(parameters[0], M_.cols());
    Eigen::Map<Eigen::VectorXd>(residuals, M_.rows()) = *weight_ * (M_ * x - c_);
    if (jacobians != nullptr && jacobians[0] != nullptr) {
      Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
          jacobians[0], M_.rows(), M_.cols()) = *weight_ * M_;
    }
    return true;
  }

 private:
  Eigen::MatrixXd M_;
  Eigen::VectorXd c_;
  const double* weight_;
};

Termination MapTermination(ceres::TerminationType t) {
  switch (t) {
    case ceres::CONVERGENCE:
    case ceres::USER_SUCCESS:
      return Termination::kConverged;
    case ceres::NO_CONVERGENCE:
      return Termination::kMaxIterations;
    case ceres::FAILURE:
    case ceres::USER_FAILURE:
      return Termination::kNumericalFailure;
  }
  return Termination::kNumericalFailure;
}

}  // namespace

Status ValidateCeresSolverOptions(const CeresSolverOptions& options) {
  ceres::LinearSolverType type;
  if (!ParseLinearSolver(options.linear_solver, &type)) {
    return Status::Error("unknown Ceres linear solver '" + options.linear_solver +
                         "' (auto, dense_qr, dense_normal_cholesky, sparse_normal_cholesky, "
                         "dense_schur, sparse_schur, iterative_schur, cgnr)");
  }
  {
    // Also catches solvers this Ceres build lacks (e.g. sparse ones without SuiteSparse).
    ceres::Solver::Options probe;
    probe.linear_solver_type = type;
    std::string error;
    if (!probe.IsValid(&error)) {
      return Status::Error("Ceres linear solver '" + options.linear_solver + "': " + error);
    }
  }
  if (Status s = ValidateCalibrationProblemOptions(internal::CeresProblemOptions(options, 0));
      !s.ok()) {
    return s;
  }
  if (options.max_iterations < 1) return Status::Error("max_iterations must be >= 1");
  if (options.num_threads < 1) return Status::Error("num_threads must be >= 1");
  if (options.rows_per_block < 0) return Status::Error("rows_per_block must be >= 0");
  if (const std::string e = ValidateConvergenceOptions(options.convergence); !e.empty()) {
    return Status::Error(e);
  }
  return Status::Ok();
}

std::string CeresLinearSolverFor(const CeresSolverOptions& options, double condition_number,
                                 int batched_rows) {
  const std::string& requested = options.linear_solver;
  if (requested != "auto" && requested != "dense_qr") return requested;
  // Dense QR would copy the 3N x P Jacobian (650 MB more for 10^6 rows) to factor it; the normal
  // equations are P x P, and LM's Jacobi scaling keeps them well conditioned.
  if (batched_rows > 1) return "dense_normal_cholesky";
  if (requested == "dense_qr") return requested;
  // The normal equations square the condition number: a step solved from them has a relative
  // error of about kappa^2 eps (kappa of the column-scaled Jacobian, which LM's Jacobi scaling
  // solves with). At kappa <= 1e4 that is 2e-8 of the step, and LM converges to the same point
  // (where the gradient J^T r, formed exactly either way, vanishes). The check's kappa is that of
  // the solved columns at the start; kept QR where it may not describe the solve: the full
  // parameterization (gauge directions: rank-deficient), robust losses (rows reweighted during
  // the solve) and the gravity tilt (a bilinear block whose columns change with the compliance).
  const bool normal_equations =
      options.parameterization == ParameterizationKind::kIdentifiable && options.loss == "none" &&
      !internal::RequestsNonlinearBlocks(options) &&
      condition_number <= CeresSolverOptions::kNormalEquationsMaxCondition;
  return normal_equations ? "dense_normal_cholesky" : "dense_qr";
}

namespace {

// The stopping rules' watch of the solve (ConvergenceWatch): the step in the solved blocks'
// coordinates (full: of the solved frames), the standard deviations from the check's J^T J.
void SetUpWatch(const CalibrationProblem& builder, const ProblemAnalysis& analysis,
                const CeresSolverOptions& options, ConvergenceWatch* watch) {
  const Parameterization& all = builder.parameterization();
  const bool full = options.parameterization == ParameterizationKind::kFull;
  const int per_row = TrackerResiduals(TrackerKindId(options.use_orientation));
  watch->options = options.convergence;
  watch->p = &all;
  const std::vector<int> sizes = builder.tangent_sizes();
  const std::vector<int> offsets = builder.tangent_offsets();
  for (size_t b = 0; b < sizes.size(); ++b) {
    if (full && offsets[b] >= all.num_frame_parameters()) break;
    for (int c = 0; c < sizes[b]; ++c) watch->columns.push_back(offsets[b] + c);
  }
  watch->dof = static_cast<long>(per_row) * builder.data().size() - analysis.num_parameters;
  if (!full) watch->H = analysis.normal_matrix;
  if (full) FullParameterizationWatch(builder, options.sigma, analysis.rank, watch);
}

// The prior's residual blocks on the problem's parameter blocks, weighted with s / sigma
// (*prior_weight, read at every evaluation): s from what the first Gauss-Newton step is expected to
// leave (prior_terms.h), in *s2. The watch's J^T J gets the prior's information.
void AddPriorResiduals(CalibrationProblem& builder, const CeresSolverOptions& options,
                       ceres::Problem* problem, ConvergenceWatch* watch, double* prior_weight,
                       double* s2) {
  const internal::ResolvedPrior& prior = builder.setup().prior;
  const Parameterization& all = builder.parameterization();
  const Parameterization& solved = builder.SolvedParameterization();
  const RobotModel& nominal = builder.nominal();
  const bool full = options.parameterization == ParameterizationKind::kFull;
  const ProblemNormalEquations ne = builder.NormalEquations();
  const double c2 = options.sigma * options.sigma;
  *s2 = internal::PriorStepDataVariance(
      prior, c2 * ne.H, c2 * ne.g, c2 * ne.cost,
      internal::LinearizePrior(prior, solved, nominal, builder.JointState()), watch->dof);
  *prior_weight = std::sqrt(*s2) / options.sigma;
  const int n = nominal.num_joints();
  for (int f = 0; f < nominal.num_frames(); ++f) {
    double* block = builder.frame_block(f);
    if (block == nullptr || all.basis[f].cols() == 0) continue;
    const SE3d& ref = f < n ? prior.reference.joints[f].origin : prior.reference.tools[f - n].origin;
    problem->AddResidualBlock(new ceres::AutoDiffCostFunction<FramePriorResidual, 6, 7>(
                                  new FramePriorResidual(ref, prior.frame_sqrt[f], prior_weight)),
                              nullptr, block);
  }
  for (size_t b = 0; b < all.joint_blocks.size(); ++b) {
    double* block = builder.joint_block(static_cast<int>(b));
    if (block == nullptr || all.joint_blocks[b].basis.cols() == 0) continue;
    problem->AddResidualBlock(
        new JointPriorResidual(prior.term_sqrt[b] * all.joint_blocks[b].basis,
                               prior.term_sqrt[b] * prior.term_reference[b], prior_weight),
        nullptr, block);
  }
  if (!full && watch->H.rows() == solved.num_parameters) {
    internal::AddPrior(internal::LinearizePrior(prior, solved, nominal, builder.JointState()), *s2,
                       &watch->H, nullptr);
  }
}

// Ceres's options of the solve: Levenberg-Marquardt with the linear solver CeresLinearSolverFor
// picks, the state updated every iteration (the history callback reads it).
ceres::Solver::Options SolverOptionsOf(const CeresSolverOptions& options, double condition_number,
                                       int batched_rows) {
  ceres::Solver::Options solver_options;
  CHECK(ParseLinearSolver(CeresLinearSolverFor(options, condition_number, batched_rows),
                          &solver_options.linear_solver_type));
  solver_options.minimizer_type = ceres::TRUST_REGION;
  solver_options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.num_threads = options.num_threads;
  solver_options.function_tolerance = options.function_tolerance;
  solver_options.gradient_tolerance = options.gradient_tolerance;
  solver_options.parameter_tolerance = options.parameter_tolerance;
  solver_options.minimizer_progress_to_stdout = options.verbose;
  solver_options.logging_type = options.verbose ? ceres::PER_MINIMIZER_ITERATION : ceres::SILENT;
  solver_options.update_state_every_iteration = true;
  return solver_options;
}

// The prior's data variance at the solution: solved again (from the solution) until it settles,
// the fixed point the linear solver's iterations reach (prior.h). Returns the prior's cost (in
// units of s2) at the solution.
double SettlePriorWeight(const CalibrationProblem& builder, const CeresSolverOptions& options,
                         long prior_dof, const ceres::Solver::Options& solver_options,
                         ceres::Problem* problem, ceres::Solver::Summary* summary,
                         double* prior_weight, double* s2) {
  const internal::ResolvedPrior& prior = builder.setup().prior;
  const Parameterization& solved = builder.SolvedParameterization();
  const double cost_scale = options.sigma * options.sigma;
  auto prior_cost_now = [&]() {
    return internal::LinearizePrior(prior, solved, builder.Model(), builder.JointState()).cost();
  };
  constexpr int kPriorRounds = 8;
  for (int round = 0; round < kPriorRounds; ++round) {
    const double prior_cost = prior_cost_now();
    const double data_cost = summary->final_cost * cost_scale - *s2 * prior_cost;
    const double s2_new = internal::PriorDataVariance(prior, data_cost, prior_dof);
    if (MapTermination(summary->termination_type) != Termination::kConverged ||
        std::abs(s2_new / *s2 - 1) <= 1e-4) {
      break;
    }
    *s2 = s2_new;
    *prior_weight = std::sqrt(*s2) / options.sigma;
    ceres::Solve(solver_options, problem, summary);
  }
  return prior_cost_now();
}

// The posterior covariance with the prior: the data's J^T J and s2 times the prior's, in the
// solved numbering; with what the prior contributed.
Status PosteriorCovariance(const CalibrationProblem& builder, double cost_scale, double s2,
                           double prior_cost, CalibrationResult* result) {
  const internal::ResolvedPrior& prior = builder.setup().prior;
  const ProblemNormalEquations ne = builder.NormalEquations();
  const Eigen::MatrixXd H_data = cost_scale * ne.H;
  const internal::PriorRows rows = internal::LinearizePrior(
      prior, builder.SolvedParameterization(), builder.Model(), builder.JointState());
  Eigen::MatrixXd H = H_data;
  internal::AddPrior(rows, s2, &H, nullptr);
  const Eigen::VectorXd d = internal::ColumnScale(H);
  const Eigen::LLT<Eigen::MatrixXd> llt(d.asDiagonal() * H * d.asDiagonal());
  Status s = Status::Ok();
  if (llt.info() != Eigen::Success) {
    s = Status::Error("the posterior's normal matrix is not positive definite");
  } else {
    result->covariance = cost_scale * (d.asDiagonal() *
                                       InverseFromCholeskyFactor(llt.matrixLLT()) * d.asDiagonal());
  }
  result->prior_data_sigma = std::sqrt(s2);
  result->prior_cost = s2 * prior_cost;
  internal::PriorContribution(rows, H_data, s2, &result->prior_standard_deviation,
                              &result->data_share);
  return s;
}

// The covariance in the tangent spaces, in the parameterization's order (builder's numbering);
// a failure is appended to *message.
void SolutionCovariance(CalibrationProblem& builder, const CeresSolverOptions& options,
                        ceres::Problem* problem, int rank, int identifiable, double s2,
                        double prior_cost, CalibrationResult* result, std::string* message) {
  const bool full = options.parameterization == ParameterizationKind::kFull;
  const double cost_scale = options.sigma * options.sigma;
  // From the normal equations when they are the whole problem (no robust loss) and full rank
  // (identifiable parameterization), or for batched rows: ceres::Covariance would form the dense
  // Jacobian of every row (650 MB for 10^6 rows) and take its SVD, the most expensive step of a
  // 1000-row calibration with joint-space terms; the normal equations are formed by the joint
  // blocks' structure, and the same rank test refuses a rank-deficient Jacobian.
  // (A block kind's block, block_kind.h: the gravity tilt's bilinear one, keeps ceres::Covariance:
  // its a-priori form, as before.)
  const bool normal_equations =
      builder.BatchedRows() > 1 || (!full && options.loss == "none" &&
                                    !internal::HasNonlinearBlocks(builder.parameterization()));
  // Full parameterization: truncated to the identifiable rank, as the steps were measured.
  int null_space_rank = -1;
  if (full) {
    int tangent = 0;
    for (int s : builder.tangent_sizes()) tangent += s;
    null_space_rank = std::max(0, tangent - rank);
  }
  Status s = Status::Ok();
  if (builder.setup().prior.active) {
    s = PosteriorCovariance(builder, cost_scale, s2, prior_cost, result);
  } else {
    s = normal_equations
            ? builder.NormalEquationsCovariance(&result->covariance, null_space_rank)
            : builder.Covariance(problem, options.num_threads, &result->covariance,
                                 null_space_rank);
  }
  if (!s.ok()) {
    *message += "; " + s.message();
  } else if (options.a_posteriori_covariance) {
    const int per_row = TrackerResiduals(TrackerKindId(options.use_orientation));
    const long dof = static_cast<long>(per_row) * builder.data().size() - identifiable;
    if (dof > 0) {
      result->covariance *= 2.0 * result->final_cost / cost_scale / static_cast<double>(dof);
    }
  }
}

// The bilinear blocks' results (block_kind.h: the gravity tilt's); their standard deviations a
// posteriori as both solvers report them (calibration.h), the a-priori ones (sigma) kept beside.
void BlockKindResults(const CalibrationProblem& builder, const CeresSolverOptions& options,
                      int identifiable, double final_cost, CalibrationResult* result) {
  const Parameterization& all = builder.parameterization();
  internal::FillBlockKindResults(all, builder.JointState(), result->covariance, result);
  if (options.a_posteriori_covariance) return;
  const int per_row = TrackerResiduals(TrackerKindId(options.use_orientation));
  const long dof = static_cast<long>(per_row) * builder.data().size() - identifiable;
  const double factor = dof > 0 ? std::sqrt(2.0 * final_cost / static_cast<double>(dof)) : 0.0;
  for (const internal::BlockKind* kind : internal::BlockKinds()) {
    const internal::BilinearBlockKind* bilinear = kind->bilinear();
    if (bilinear != nullptr && bilinear->In(all)) bilinear->ScaleToAPosteriori(factor, result);
  }
}

}  // namespace

CalibrationResult CalibrateCeres(const RobotModel& nominal, const MeasurementSet& data,
                                 const CeresSolverOptions& options) {
  {
    const Status s = ValidateCeresSolverOptions(options);
    CHECK(s.ok()) << s.message();
  }
  if (options.use_orientation && !data.has_orientation()) {
    CalibrationResult result;
    result.model = nominal;
    result.termination = Termination::kNotIdentifiable;
    result.message = "pose-based calibration needs measured orientations (quat_x..quat_w columns)";
    return result;
  }
  // Every decision (parameterization, frames solved, prior) is the problem's (problem_setup.h).
  CalibrationProblem builder(nominal, data, internal::CeresProblemOptions(options, data.size()));
  return internal::CalibrateCeresOn(&builder, options);
}

namespace internal {

CalibrationResult CalibrateCeresOn(CalibrationProblem* problem_in,
                                   const CeresSolverOptions& options_in) {
  const auto start = std::chrono::steady_clock::now();
  CHECK(problem_in != nullptr);
  CalibrationProblem& builder = *problem_in;
  {
    const Status s = ValidateCeresSolverOptions(options_in);
    CHECK(s.ok()) << s.message();
  }
  // The problem's decisions, sigma and loss, read below through `options` as before.
  CeresSolverOptions options = options_in;
  static_cast<ProblemCostOptions&>(options) = builder.options();
  CalibrationResult result;
  result.model = builder.Model();
  auto finish = [&](Termination t, const std::string& message) {
    result.termination = t;
    result.message = message;
    result.wall_time_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
  };
  if (!builder.block_status().ok()) {
    return finish(Termination::kNotIdentifiable, builder.block_status().message());
  }
  // The result's parameterization is the solved one, unmeasured tools left out and listed as not
  // identifiable (with the reason), as the linear solver's; the builder's numbering (every tool)
  // is used during the solve and mapped at the end (SolvedCovariance).
  const Parameterization& all = builder.parameterization();
  result.parameterization = builder.SolvedParameterization();
  result.joint_terms = builder.JointTerms();

  // ---- The identifiability check of the linear solver (same thresholds, same messages), on the
  // identifiable directions of the frames that are solved (unmeasured tools are not).
  const ProblemAnalysis analysis = builder.Analyze(options.max_condition_number);
  // The prior (lpoe/model/prior.h): identifiable parameterization only; an informative one lets rows
  // that cannot identify the model alone calibrate.
  const bool use_prior = builder.setup().prior.active;
  const bool informative = use_prior && builder.setup().prior.informative;
  if (analysis.num_equations < analysis.num_parameters && !informative) {
    return finish(Termination::kNotIdentifiable, analysis.message);
  }
  if (!analysis.finite) return finish(Termination::kNumericalFailure, analysis.message);
  result.rank = analysis.rank;
  result.condition_number = analysis.condition_number;
  result.singular_values = analysis.singular_values;
  if (!analysis.identifiable && !(informative && analysis.finite)) {
    return finish(Termination::kNotIdentifiable, analysis.message);
  }
  const int identifiable = analysis.num_parameters;

  ConvergenceWatch watch;
  SetUpWatch(builder, analysis, options, &watch);
  ceres::Problem problem;
  builder.AddTo(&problem);
  // The prior's residual blocks on the same parameter blocks, weighted with s / sigma: s from the
  // start's residuals, then (below) from the solution's until it settles.
  const long prior_dof = watch.dof;
  double prior_weight = 0;
  double s2 = 0;
  if (use_prior) AddPriorResiduals(builder, options, &problem, &watch, &prior_weight, &s2);

  // ---- Solve.
  const ceres::Solver::Options solver_options =
      SolverOptionsOf(options, analysis.condition_number, builder.BatchedRows());
  const double cost_scale = options.sigma * options.sigma;
  HistoryCallback callback(builder, cost_scale, &result.history, options.on_iteration, &watch);
  ceres::Solver::Options with_callback = solver_options;
  with_callback.callbacks.push_back(&callback);
  ceres::Solver::Summary summary;
  ceres::Solve(with_callback, &problem, &summary);
  if (options.verbose) LOG(INFO) << summary.FullReport();
  double prior_cost = 0;
  if (use_prior) {
    prior_cost = SettlePriorWeight(builder, options, prior_dof, with_callback, &problem, &summary,
                                   &prior_weight, &s2);
  }

  result.model = builder.Model();
  result.joint_terms = builder.JointTerms();
  result.iterations = summary.num_successful_steps + summary.num_unsuccessful_steps;
  result.final_cost = summary.final_cost * cost_scale - s2 * prior_cost;
  const Termination termination = MapTermination(summary.termination_type);
  std::string message = "ceres: " + summary.message;
  if (summary.termination_type == ceres::USER_SUCCESS && watch.decision.converged()) {
    result.stop_rule = watch.decision.rule;
    message = "ceres: " + watch.decision.message;
  }
  if (termination == Termination::kNumericalFailure) {
    internal::FillBlockKindResults(all, builder.JointState(), Eigen::MatrixXd(), &result);
    return finish(termination, message);
  }
  if (options.compute_covariance && termination == Termination::kConverged) {
    SolutionCovariance(builder, options, &problem, analysis.rank, identifiable, s2, prior_cost,
                       &result, &message);
  }
  BlockKindResults(builder, options, identifiable, summary.final_cost, &result);
  if (result.covariance.rows() == all.num_parameters) {
    result.covariance = SolvedCovariance(builder, result.covariance);
  }
  return finish(termination, message);
}

}  // namespace internal

}  // namespace lpoe
