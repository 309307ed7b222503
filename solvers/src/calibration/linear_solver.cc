#include "lpoe/linear_solver.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <glog/logging.h>

#include "calibration/block_kind.h"
#include "identifiability/identifiability.h"
#include "calibration/prior_terms.h"
#include "calibration/problem_setup.h"
#include "lpoe/kinematics/eigen_decompositions.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/problem_builder.h"
#include "calibration/solve_on_problem.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "identifiability/structural_identifiability.h"

namespace lpoe {
namespace {

// Step halvings tried when a Gauss-Newton step raises the cost.
constexpr int kMaxHalvings = 12;
// A step is accepted if it does not raise the cost by more than this relative amount (round-off).
constexpr double kCostIncreaseTolerance = 1e-10;

using Linearization = internal::NormalEquations;

}  // namespace

namespace internal {

void LeaveOutUnmeasuredTools(const RobotModel& model, const MeasurementSet& data,
                             Parameterization* p) {
  const int n = model.num_joints();
  std::vector<bool> measured(model.num_tools(), false);
  for (int r = 0; r < data.size(); ++r) measured[data.target(r)] = true;
  bool any = false;
  for (int t = 0; t < model.num_tools(); ++t) any = any || !measured[t];
  if (!any) return;
  Parameterization out = *p;
  out.parameters.clear();
  out.num_parameters = 0;
  for (size_t f = 0; f < p->basis.size(); ++f) {
    const bool skip = static_cast<int>(f) >= n && !measured[f - n];
    for (int c = 0; c < p->basis[f].cols(); ++c) {
      Direction d = p->parameters[p->offset[f] + c];
      if (skip) {
        d.reason = "tool never measured in these data: not identified, kept as given";
        out.unidentifiable.push_back(d);
      } else {
        out.parameters.push_back(d);
      }
    }
    if (skip) out.basis[f] = Eigen::MatrixXd::Zero(6, 0);
    out.offset[f] = out.num_parameters;
    out.num_parameters += static_cast<int>(out.basis[f].cols());
  }
  for (JointBlock& b : out.joint_blocks) {  // after the frames, shifted
    const int old_offset = b.offset;
    b.offset = out.num_parameters;
    for (int c = 0; c < b.basis.cols(); ++c) out.parameters.push_back(p->parameters[old_offset + c]);
    out.num_parameters += static_cast<int>(b.basis.cols());
  }
  for (BilinearBlock& b : out.bilinear_blocks) {  // after the joint blocks
    const int old_offset = b.offset;
    b.offset = out.num_parameters;
    const int m = b.effect->num_parameters();
    for (int a = 0; a < m; ++a) out.parameters.push_back(p->parameters[old_offset + a]);
    out.num_parameters += m;
  }
  *p = std::move(out);
}

}  // namespace internal

namespace {

// The normal equations' options of the solver's measurements (position or pose rows).
internal::NormalEquationsOptions RowsOf(const LinearSolverOptions& options) {
  internal::NormalEquationsOptions o;
  o.use_orientation = options.use_orientation;
  o.orientation_weight = options.orientation_weight;
  return o;
}

using internal::ColumnScale;

// Least-squares step x of J x = y. Full parameterization: at most `rank` singular directions (the
// identifiable count): the gauge directions are null at the start, but a structurally lost one
// (structural_identifiability.h) comes back weakly through them once the model moves, and a
// pseudo-inverse would take ever larger steps along it.
// `factor`, `scale` (optional, not with `full`): the Cholesky factor of the column-scaled normal
// matrix and the scale, for the standard deviations of the same linearization.
Eigen::VectorXd SolveStep(const Linearization& lin, bool full, int rank,
                          const LinearSolverOptions& options,
                          Eigen::LLT<Eigen::MatrixXd>* factor = nullptr,
                          Eigen::VectorXd* scale = nullptr) {
  const Eigen::VectorXd d = ColumnScale(lin.H);
  if (full) {
    // Minimum-norm solution of the rank-deficient system (the paper's eq. (32) read as a
    // pseudo-inverse), on the column-scaled stacked Jacobian for accuracy.
    const Eigen::MatrixXd Js = lin.J * d.asDiagonal();
    Eigen::BDCSVD<Eigen::MatrixXd> svd(Js, Eigen::ComputeThinU | Eigen::ComputeThinV);
    const Eigen::VectorXd& s = svd.singularValues();
    int r = 0;
    while (r < s.size() && r < rank && s(r) > options.pseudo_inverse_tolerance * s(0)) ++r;
    // The minimum-norm solution in scaled coordinates; mapped back by d.
    const Eigen::VectorXd z =
        (svd.matrixU().leftCols(r).transpose() * lin.y).cwiseQuotient(s.head(r));
    return d.asDiagonal() * (svd.matrixV().leftCols(r) * z);
  }
  const Eigen::MatrixXd Hs = d.asDiagonal() * lin.H * d.asDiagonal();
  const Eigen::VectorXd gs = d.asDiagonal() * lin.g;
  Eigen::LLT<Eigen::MatrixXd> llt(Hs);
  if (llt.info() != Eigen::Success) return Eigen::VectorXd::Constant(lin.g.size(), NAN);
  Eigen::VectorXd x = d.asDiagonal() * llt.solve(gs);
  if (factor != nullptr) *factor = std::move(llt);
  if (scale != nullptr) *scale = d;
  return x;
}

IterationRecord Record(int iteration, const Linearization& lin) {
  IterationRecord r;
  r.iteration = iteration;
  r.cost = lin.cost;
  r.max_error = lin.max_error;
  r.mean_error = lin.mean_error;
  return r;
}

}  // namespace

const char* TerminationName(Termination t) {
  switch (t) {
    case Termination::kConverged:
      return "converged";
    case Termination::kMaxIterations:
      return "not converged (iteration limit)";
    case Termination::kNotIdentifiable:
      return "not identifiable";
    case Termination::kNumericalFailure:
      return "numerical failure";
  }
  return "unknown";
}

namespace {

// Frozen joint blocks (structured path): the joint-space columns J_q(q_eff) R change with the
// geometry and the terms by about their relative size (1e-3), so the iterations form the frames'
// block, the gradient and the cost exactly and keep the joint blocks of H (frames x joint,
// joint x joint) from the last exact linearization: the step solves the exact gradient with a
// slightly older H, which converges to the same solution (where the gradient is zero) with a
// contraction of about that relative change per iteration. When the steps stop shrinking by
// kFrozenContraction the blocks are formed again at the current point, and the covariance is
// always computed from exact ones.
constexpr double kFrozenContraction = 0.05;

// One run of the linear solver on a CalibrationProblem (problem_builder.h): a Gauss-Newton loop
// with backtracking over the problem's normal equations (plus the prior's rows). Every decision is
// the problem's (its setup(), problem_setup.h), and so is the state: the model and the joint and
// tilt blocks are the problem's values, linearized by CalibrationProblem::Linearize and moved by
// CalibrationProblem::Update (a rejected trial step is undone with SetValues). What the solver
// keeps is the loop's own: the current linearization, the prior's rows, the frozen joint blocks.
// Run() is the loop; each stage a member function.
class LinearSolve {
 public:
  LinearSolve(CalibrationProblem* problem, const LinearSolverOptions& options,
              CalibrationResult* result, std::chrono::steady_clock::time_point start);
  // Solves; the result as CalibrateLinear returns it.
  CalibrationResult Run();

 private:
  CalibrationResult Finish(Termination t, const std::string& message);
  // The first linearization (at the start model) and the identifiability check there; false with
  // the result finished when the solve cannot go on.
  bool Start();
  bool CheckIdentifiability();
  Eigen::VectorXd JointValuesState() const;
  std::vector<JointTermValues> JointValues() const;
  // The prior's rows at the problem's current values.
  internal::PriorRows PriorAt() const;
  Linearization WithPrior(const Linearization& l, const internal::PriorRows& pr) const;
  double Total(const Linearization& l, const internal::PriorRows& pr) const;
  // The step of the current linearization (with the prior's rows when there is one).
  Eigen::VectorXd SolveCurrent(Eigen::LLT<Eigen::MatrixXd>* factor, Eigen::VectorXd* scale) const;
  // The joint blocks of H kept from the last exact linearization (see kFrozenContraction).
  void Freeze(const Linearization& l) { frozen_ = l.H.rightCols(K_); }
  void Complete(Linearization* l) const;
  Linearization Exact();
  // The warm start (see LinearSolverOptions::warm_start_rows); the subsample's iterations taken,
  // or -1 when it did not apply.
  int WarmStart(const Eigen::VectorXd& x);
  // The converged step x: the solution's model, statistics and covariance.
  CalibrationResult Converged(const Eigen::VectorXd& x, const ConvergenceDecision& decision,
                              int it);
  void FinalLinearization(const Eigen::VectorXd& x);
  void Covariance();
  // The step x with backtracking (halved while it raises the cost); false when none is accepted.
  bool TakeStep(const Eigen::VectorXd& x);
  // The result at the current point when the solve stops without converging.
  CalibrationResult Stopped(Termination t, int iterations, const std::string& message);

  CalibrationProblem& problem_;
  const MeasurementSet& data_;
  const LinearSolverOptions& options_;
  const internal::ProblemSetup& setup_;
  CalibrationResult& result_;
  const Parameterization& p_;  // result_.parameterization
  std::chrono::steady_clock::time_point start_;
  // The rows' errors of every main linearization go to options.errors->final_errors; they are
  // kept when the last one is that of the returned model.
  PositionErrorRows* errors_;
  bool errors_current_ = false;
  const bool full_;
  const bool use_prior_;
  const int K_;  // the joint-space blocks' coordinates
  const bool structured_;
  const long dof_;
  internal::JointSpaceRegressors no_regressors_;
  Eigen::MatrixXd joint_rows_;
  // The solve's linearizations: with every block exact, without the rows' errors, or with the
  // joint blocks left out (the structured iterations' frozen blocks).
  internal::NormalEquationsOptions exact_rows_;
  internal::NormalEquationsOptions exact_no_errors_;
  internal::NormalEquationsOptions gradient_only_;
  Linearization lin_;
  internal::PriorRows prior_rows_;
  // The data variance the prior's rows are weighted with (prior_terms.h).
  double s2_ = 0;
  Eigen::MatrixXd frozen_;  // P x K: H's joint columns
  double previous_cost_ = -1;
  double previous_step_ = -1;
};

LinearSolve::LinearSolve(CalibrationProblem* problem, const LinearSolverOptions& options,
                         CalibrationResult* result, std::chrono::steady_clock::time_point start)
    : problem_(*problem),
      data_(problem->data()),
      options_(options),
      setup_(problem->setup()),
      result_(*result),
      p_(result->parameterization),
      start_(start),
      errors_(options.errors ? &options.errors->final_errors : nullptr),
      full_(setup_.full),
      use_prior_(setup_.prior.active),
      K_(setup_.solved.num_joint_parameters()),
      // The rows' joint regressors do not change during the solve: evaluated once. The full
      // parameterization (stacked rows) and a block kind's solve (columns that change with the
      // state, block_kind.h: the gravity tilt) take the dense joint columns (JointRegressorRows);
      // otherwise the normal equations are formed by the joint blocks' structure
      // (normal_equations.h).
      structured_(K_ > 0 && !full_ && !internal::HasNonlinearBlocks(setup_.solved)),
      dof_(setup_.equations - setup_.identifiable) {
  if (!structured_) joint_rows_ = internal::JointRegressorRows(p_, data_);
  exact_rows_ = RowsOf(options_);
  exact_rows_.stack = full_;
  exact_rows_.joint_rows = &joint_rows_;
  exact_rows_.errors = errors_;
  exact_rows_.joint.regressors = setup_.regressors ? setup_.regressors.get() : &no_regressors_;
  exact_no_errors_ = exact_rows_;
  exact_no_errors_.errors = nullptr;
  gradient_only_ = exact_rows_;
  gradient_only_.joint.gradient_only = true;
}

CalibrationResult LinearSolve::Finish(Termination t, const std::string& message) {
  if (errors_ != nullptr && !(errors_current_ && (t == Termination::kConverged ||
                                                  t == Termination::kMaxIterations))) {
    errors_->Clear();
  }
  result_.termination = t;
  result_.message = message;
  result_.wall_time_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  return result_;
}

Eigen::VectorXd LinearSolve::JointValuesState() const {
  Eigen::VectorXd x = Eigen::VectorXd::Zero(p_.num_parameters);
  x.tail(K_) = problem_.JointState();
  return x;
}

std::vector<JointTermValues> LinearSolve::JointValues() const {
  return JointValuesOf(p_, JointValuesState());
}

internal::PriorRows LinearSolve::PriorAt() const {
  return use_prior_ ? internal::LinearizePrior(setup_.prior, p_, problem_.Model(),
                                               problem_.JointState())
                    : internal::PriorRows();
}

// The prior's rows at the current point and the data variance s2 they are weighted with (that of
// the current point's residuals unless the prior fixes it): the step solves the data's normal
// equations plus s2 A^T A, the cost compared is the data's plus s2 times the prior's.
Linearization LinearSolve::WithPrior(const Linearization& l, const internal::PriorRows& pr) const {
  Linearization c;
  c.H = l.H;
  c.g = l.g;
  c.cost = l.cost;
  c.finite = l.finite;
  internal::AddPrior(pr, s2_, &c.H, &c.g);
  return c;
}

double LinearSolve::Total(const Linearization& l, const internal::PriorRows& pr) const {
  return l.cost + s2_ * pr.cost();
}

Eigen::VectorXd LinearSolve::SolveCurrent(Eigen::LLT<Eigen::MatrixXd>* factor,
                                          Eigen::VectorXd* scale) const {
  return use_prior_ ? SolveStep(WithPrior(lin_, prior_rows_), full_, setup_.identifiable, options_,
                                factor, scale)
                    : SolveStep(lin_, full_, setup_.identifiable, options_, factor, scale);
}

void LinearSolve::Complete(Linearization* l) const {
  l->H.rightCols(K_) = frozen_;
  l->H.bottomLeftCorner(K_, p_.num_parameters - K_) =
      frozen_.topRows(p_.num_parameters - K_).transpose();
}

Linearization LinearSolve::Exact() {
  Linearization l = problem_.Linearize(exact_no_errors_);
  Freeze(l);
  return l;
}

bool LinearSolve::CheckIdentifiability() {
  // At the start values, by the problem's check (CalibrationProblem::AnalyzeNormalMatrix, the Ceres
  // solver's too) on this linearization, with the prior's information when it is informative.
  const bool informative = use_prior_ && setup_.prior.informative;
  const ProblemAnalysis a = problem_.AnalyzeNormalMatrix(
      informative ? WithPrior(lin_, prior_rows_).H : lin_.H, options_.max_condition_number);
  result_.rank = a.rank;
  result_.condition_number = a.condition_number;
  result_.singular_values = a.singular_values;
  if (a.identifiable) return true;
  Finish(Termination::kNotIdentifiable, a.message);
  return false;
}

bool LinearSolve::Start() {
  if (errors_ != nullptr) {
    errors_->Clear();
    options_.errors->have_start_statistics = false;
  }
  if (setup_.equations < setup_.identifiable && !(use_prior_ && setup_.prior.informative)) {
    Finish(Termination::kNotIdentifiable,
           internal::TooFewEquationsMessage(data_.size(), setup_.equations, setup_.identifiable,
                                            setup_.per_row));
    return false;
  }
  // With joint-space terms, the analysis that reduced them also gave the normal equations at the
  // nominal model with every term whole: the first linearization is their projection onto the
  // reduced blocks (no second pass over the rows).
  lin_ = structured_ && setup_.analysed && problem_.JointState().isZero() &&
                 internal::SameFrameDirections(setup_.analysed_parameterization, p_)
             ? internal::ProjectJointBlocks(*setup_.analysed, p_)
             : problem_.Linearize(exact_rows_);
  errors_current_ = errors_ != nullptr && !errors_->empty();
  if (errors_current_ && options_.errors->want_start_statistics && lin_.finite) {
    options_.errors->start_statistics = errors_->Statistics();
    options_.errors->have_start_statistics = true;
  }
  if (!lin_.finite) {
    Finish(Termination::kNumericalFailure,
           "non-finite residuals or Jacobian at the nominal model (check the input values)");
    return false;
  }
  result_.history.push_back(Record(0, lin_));
  result_.joint_terms = JointValues();  // zero until solved
  prior_rows_ = PriorAt();
  s2_ = use_prior_ ? internal::PriorDataVariance(setup_.prior, lin_.cost, dof_) : 0.0;
  if (!CheckIdentifiability()) return false;
  if (structured_) Freeze(lin_);
  return true;
}

// The warm start: at the first iteration the step x computed on all rows at the start model is
// taken, and the solve continues on every `every`-th row (kept in order) to its own convergence;
// all rows are then linearized at that solution (its errors, when kept, replace the start's),
// which must not raise the cost of the start model. Records the subsample's iterations (with
// their row count) and the new linearization's; returns the number of subsample iterations
// recorded, or -1 when the warm start did not apply (then nothing changed but the kept errors,
// no longer current: the caller continues as without it).
int LinearSolve::WarmStart(const Eigen::VectorXd& x) {
  if (!x.allFinite()) return -1;
  const int every = (data_.size() + options_.warm_start_rows - 1) / options_.warm_start_rows;
  std::vector<int> rows;
  rows.reserve(data_.size() / every + 1);
  for (int r = 0; r < data_.size(); r += every) rows.push_back(r);
  const MeasurementSet subset = data_.Subset(rows);
  RobotModel first = problem_.Model();
  ApplyUpdate(p_, x, &first);
  LinearSolverOptions sub = options_;
  sub.parameterization_override = &p_;  // the same directions (and no warm start of its own)
  sub.parameterization = problem_.options().parameterization;
  sub.use_orientation = problem_.options().use_orientation;
  sub.orientation_weight = problem_.options().orientation_weight;
  sub.structure_reference = nullptr;
  sub.compute_covariance = false;
  sub.verbose = false;
  sub.on_iteration = nullptr;
  sub.errors = nullptr;
  sub.max_iterations = std::max(1, options_.max_iterations - 2);
  sub.prior = setup_.anchored_prior;
  const CalibrationResult s = CalibrateLinear(first, subset, sub);
  if (!s.converged() || s.history.empty()) return -1;
  // The subsample's solution, linearized on every row.
  const CalibrationProblem::Values kept = problem_.values();
  problem_.SetFrames(s.model);
  Linearization at = problem_.Linearize(exact_rows_);
  errors_current_ = false;
  const internal::PriorRows at_prior = PriorAt();
  if (!at.finite ||
      !(Total(at, at_prior) <= Total(lin_, prior_rows_) * (1 + kCostIncreaseTolerance) + 1e-300)) {
    problem_.SetValues(kept);
    return -1;
  }
  prior_rows_ = at_prior;
  errors_current_ = errors_ != nullptr && !errors_->empty();
  result_.history.back().step_norm = x.norm();
  // The subsample's records but its last (the point linearized on all rows now).
  const int taken = static_cast<int>(s.history.size()) - 1;
  for (int k = 0; k < taken; ++k) {
    IterationRecord r = s.history[k];
    r.iteration = 1 + k;
    r.rows = subset.size();
    result_.history.push_back(r);
    if (options_.on_iteration) options_.on_iteration(r);
  }
  result_.warm_start_rows = subset.size();
  lin_ = std::move(at);
  result_.history.push_back(Record(1 + taken, lin_));
  if (options_.on_iteration) options_.on_iteration(result_.history.back());
  return taken;
}

// With frozen joint blocks the contraction per step is about their relative change, not
// quadratic: the last (tiny) step is taken too, and the solution's normal equations are formed
// exactly (the covariance's, and the final cost).
void LinearSolve::FinalLinearization(const Eigen::VectorXd& x) {
  const CalibrationProblem::Values kept = problem_.values();
  problem_.Update(x);
  Linearization last = Exact();
  const internal::PriorRows last_prior = PriorAt();
  if (last.finite &&
      Total(last, last_prior) <= Total(lin_, prior_rows_) * (1 + kCostIncreaseTolerance) + 1e-300) {
    lin_ = std::move(last);
    prior_rows_ = last_prior;
  } else {
    problem_.SetValues(kept);
    lin_ = Exact();
  }
}

// s^2 (J^T J)^-1 (with the prior's rows: the posterior), column-scaled for accuracy.
void LinearSolve::Covariance() {
  if (!options_.compute_covariance || full_ || dof_ <= 0) return;
  const double s2_post = 2.0 * lin_.cost / static_cast<double>(dof_);
  const Eigen::MatrixXd Hc = use_prior_ ? WithPrior(lin_, prior_rows_).H : lin_.H;
  const Eigen::VectorXd d = ColumnScale(Hc);
  const Eigen::MatrixXd Hs = d.asDiagonal() * Hc * d.asDiagonal();
  const Eigen::LLT<Eigen::MatrixXd> llt(Hs);
  if (llt.info() == Eigen::Success) {
    const Eigen::MatrixXd inv = InverseFromCholeskyFactor(llt.matrixLLT());
    result_.covariance = s2_post * (d.asDiagonal() * inv * d.asDiagonal());
  }
}

CalibrationResult LinearSolve::Converged(const Eigen::VectorXd& x,
                                         const ConvergenceDecision& decision, int it) {
  if (structured_ && !lin_.joint_blocks) FinalLinearization(x);
  result_.stop_rule = decision.rule;
  result_.model = problem_.Model();
  result_.joint_terms = JointValues();
  result_.iterations = it - 1;
  result_.final_cost = lin_.cost;
  if (use_prior_) {
    // What the prior contributed (at the solution's residuals) and the posterior covariance.
    s2_ = internal::PriorDataVariance(setup_.prior, lin_.cost, dof_);
    result_.prior_data_sigma = std::sqrt(s2_);
    result_.prior_cost = s2_ * prior_rows_.cost();
    internal::PriorContribution(prior_rows_, lin_.H, s2_, &result_.prior_standard_deviation,
                                &result_.data_share);
  }
  Covariance();
  internal::FillBlockKindResults(p_, problem_.JointState(), result_.covariance, &result_);
  return Finish(Termination::kConverged, decision.message);
}

// Gauss-Newton step with backtracking: a step that raises the cost is halved.
// The trial point is the problem's (CalibrationProblem::Update); a rejected one is undone.
bool LinearSolve::TakeStep(const Eigen::VectorXd& x) {
  const CalibrationProblem::Values kept = problem_.values();
  double alpha = 1.0;
  for (int h = 0; h <= kMaxHalvings; ++h, alpha *= 0.5) {
    if (h > 0) problem_.SetValues(kept);
    problem_.Update(alpha * x);
    Linearization next = problem_.Linearize(structured_ ? gradient_only_ : exact_rows_);
    errors_current_ = false;
    if (structured_) Complete(&next);
    const internal::PriorRows next_prior = PriorAt();
    if (next.finite &&
        Total(next, next_prior) <= Total(lin_, prior_rows_) * (1 + kCostIncreaseTolerance) + 1e-300) {
      errors_current_ = errors_ != nullptr && !errors_->empty();
      previous_cost_ = Total(lin_, prior_rows_);
      lin_ = std::move(next);
      prior_rows_ = next_prior;
      return true;
    }
  }
  problem_.SetValues(kept);
  return false;
}

CalibrationResult LinearSolve::Stopped(Termination t, int iterations,
                                       const std::string& message) {
  result_.model = problem_.Model();
  result_.joint_terms = JointValues();
  internal::FillBlockKindResults(p_, problem_.JointState(), Eigen::MatrixXd(), &result_);
  result_.iterations = iterations;
  result_.final_cost = lin_.cost;
  return Finish(t, message);
}

CalibrationResult LinearSolve::Run() {
  if (!Start()) return result_;
  // Warm start (large data, linear_solver.h): the iterations that cross the model's large initial
  // errors run on a subsample; all rows are linearized again only at its solution.
  const bool warm_start = !full_ && !setup_.overridden &&
                          problem_.options().joint_terms.empty() &&
                          !internal::RequestsNonlinearBlocks(problem_.options()) && K_ == 0 &&
                          options_.warm_start_rows > 0 &&
                          data_.size() >= options_.warm_start_min_rows &&
                          data_.size() >= 2 * options_.warm_start_rows;
  ConvergenceOptions stop = options_.convergence;
  stop.step_tolerance = options_.step_tolerance;
  for (int it = 1; it <= options_.max_iterations; ++it) {
    // The step's factorization also gives the stopping rule's standard deviations.
    Eigen::LLT<Eigen::MatrixXd> factor;
    Eigen::VectorXd scale;
    if (use_prior_) {
      s2_ = internal::PriorStepDataVariance(setup_.prior, lin_.H, lin_.g, lin_.cost, prior_rows_,
                                            dof_);
    }
    Eigen::VectorXd x = SolveCurrent(&factor, &scale);
    if (structured_ && !lin_.joint_blocks &&
        (!x.allFinite() ||
         (previous_step_ >= 0 && x.norm() > kFrozenContraction * previous_step_))) {
      lin_ = Exact();
      scale.resize(0);
      x = SolveCurrent(&factor, &scale);
    }
    previous_step_ = x.norm();
    if (!x.allFinite()) {
      return Finish(Termination::kNumericalFailure,
                    "the least-squares step is not finite (numerically singular normal equations)");
    }
    const double step = x.norm();
    result_.history.back().step_norm = step;
    if (options_.verbose) {
      LOG(INFO) << "iteration " << it - 1 << ": max " << lin_.max_error << " mm, mean "
                << lin_.mean_error << " mm, |x| " << step;
    }
    ConvergenceState state;
    state.step = x;
    if (!full_) {
      state.standard_deviation =
          scale.size() == lin_.H.rows()
              ? StandardDeviationsFromFactor(factor.matrixLLT(), scale, lin_.cost, dof_)
              : StandardDeviations(use_prior_ ? WithPrior(lin_, prior_rows_).H : lin_.H,
                                   lin_.cost, dof_);
    }
    state.parameter_scale = ParameterScale(problem_.Model());
    state.cost = use_prior_ ? Total(lin_, prior_rows_) : lin_.cost;
    state.previous_cost = previous_cost_;
    const ConvergenceDecision decision = TestConvergence(stop, state);
    if (decision.converged()) return Converged(x, decision, it);
    if (it == 1 && warm_start) {
      const int taken = WarmStart(x);
      if (taken >= 0) {
        previous_cost_ = result_.history.front().cost;
        previous_step_ = -1;
        it += taken;  // the subsample's iterations; the next one is on all rows
        continue;
      }
    }
    if (!TakeStep(x)) {
      std::ostringstream os;
      os << "no step along the least-squares direction reduces the cost (|x| = " << step
         << "); the linearization is not valid here (check units, angle_unit and the base frame)";
      return Stopped(Termination::kNumericalFailure, it - 1, os.str());
    }
    result_.history.push_back(Record(it, lin_));
    if (options_.on_iteration) options_.on_iteration(result_.history.back());
  }
  std::ostringstream os;
  os << "not converged after " << options_.max_iterations << " iterations (last |x| = "
     << result_.history[result_.history.size() - 2].step_norm << ", tolerance "
     << options_.step_tolerance << ")";
  return Stopped(Termination::kMaxIterations, options_.max_iterations, os.str());
}

}  // namespace

namespace internal {

CalibrationProblemOptions LinearProblemOptions(const LinearSolverOptions& options) {
  CalibrationProblemOptions o;
  static_cast<ProblemDefinitionOptions&>(o) = options;  // sigma 1, no loss: ProblemCostOptions' defaults
  return o;
}

}  // namespace internal

CalibrationResult CalibrateLinear(const RobotModel& nominal, const MeasurementSet& data,
                                  const LinearSolverOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  CalibrationResult result;
  result.model = nominal;
  auto finish = [&](Termination t, const std::string& message) {
    if (options.errors != nullptr) {
      options.errors->final_errors.Clear();
      options.errors->have_start_statistics = false;
    }
    result.termination = t;
    result.message = message;
    result.wall_time_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
  };
  CHECK_EQ(data.num_joints(), nominal.num_joints()) << "measurements do not match the model";
  for (int r = 0; r < data.size(); ++r) {
    CHECK(data.target(r) >= 0 && data.target(r) < nominal.num_tools()) << "bad target in row " << r;
  }
  if (options.use_orientation && !data.has_orientation()) {
    return finish(Termination::kNotIdentifiable,
                  "pose-based calibration needs measured orientations (quat_x..quat_w columns)");
  }
  // Every decision once, as the Ceres solver's problem makes them (problem_setup.h).
  internal::ProblemSetupRequest request = internal::ProblemSetupRequestOf(options);
  request.parameterization_override = options.parameterization_override;
  auto setup = std::make_shared<const internal::ProblemSetup>(
      internal::SetUpProblem(nominal, data, request));
  result.parameterization = setup->solved;
  if (!setup->block_status.ok()) {
    return finish(Termination::kNotIdentifiable, setup->block_status.message());
  }
  CalibrationProblem problem(nominal, data, internal::LinearProblemOptions(options), std::move(setup));
  return LinearSolve(&problem, options, &result, start).Run();
}

namespace internal {

CalibrationResult CalibrateLinearOn(CalibrationProblem* problem,
                                    const LinearSolverOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  CHECK(problem != nullptr);
  CalibrationResult result;
  result.model = problem->Model();
  result.parameterization = problem->SolvedParameterization();
  if (!problem->block_status().ok()) {
    if (options.errors != nullptr) {
      options.errors->final_errors.Clear();
      options.errors->have_start_statistics = false;
    }
    result.termination = Termination::kNotIdentifiable;
    result.message = problem->block_status().message();
    result.wall_time_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
  }
  return LinearSolve(problem, options, &result, start).Run();
}

}  // namespace internal

}  // namespace lpoe
