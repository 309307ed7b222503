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

#include "calibration/gravity_tilt.h"
#include "identifiability/identifiability.h"
#include "calibration/prior_terms.h"
#include "lpoe/eigen_decompositions.h"
#include "lpoe/kinematics.h"
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
  if (out.gravity_tilt) {  // after the joint blocks
    out.tilt_offset = out.num_parameters;
    for (int a = 0; a < 2; ++a) out.parameters.push_back(p->parameters[p->tilt_offset + a]);
    out.num_parameters += 2;
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

// The identifiability check shared with the Ceres solver (identifiability.h).
using internal::Analyze;
using internal::ColumnScale;
using internal::Identifiability;

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

CalibrationResult CalibrateLinear(const RobotModel& nominal, const MeasurementSet& data,
                                  const LinearSolverOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  CalibrationResult result;
  result.model = nominal;
  // The rows' errors of every main linearization go to options.errors->final_errors; they are kept
  // when the last one is that of the returned model.
  PositionErrorRows* errors = options.errors ? &options.errors->final_errors : nullptr;
  if (errors != nullptr) {
    errors->Clear();
    options.errors->have_start_statistics = false;
  }
  bool errors_current = false;
  auto finish = [&](Termination t, const std::string& message) {
    if (errors != nullptr && !(errors_current && (t == Termination::kConverged ||
                                                  t == Termination::kMaxIterations))) {
      errors->Clear();
    }
    result.termination = t;
    result.message = message;
    result.wall_time_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
  };

  const DataKind kind = options.use_orientation ? DataKind::kPose : DataKind::kPosition;
  CHECK_EQ(data.num_joints(), nominal.num_joints()) << "measurements do not match the model";
  for (int r = 0; r < data.size(); ++r) {
    CHECK(data.target(r) >= 0 && data.target(r) < nominal.num_tools()) << "bad target in row " << r;
  }
  if (options.use_orientation && !data.has_orientation()) {
    return finish(Termination::kNotIdentifiable,
                  "pose-based calibration needs measured orientations (quat_x..quat_w columns)");
  }
  const bool override_basis = options.parameterization_override != nullptr;
  CHECK(!override_basis || options.joint_terms.empty())
      << "joint-space terms with a parameterization override";
  // With joint-space terms, the analysis that reduces them also gives the rows' regressors and the
  // normal equations at the nominal model with every term whole: the first linearization below is
  // their projection onto the reduced blocks (no second pass over the rows).
  internal::NormalEquations analysed;
  internal::JointSpaceRegressors regressors;
  Parameterization analysed_p;
  internal::SolverParameterizationRequest request = internal::ParameterizationRequestOf(options);
  request.analysed = &analysed;
  request.regressors = &regressors;
  request.analysed_parameterization = &analysed_p;
  result.parameterization = override_basis
                                ? *options.parameterization_override
                                : internal::SolverParameterization(nominal, data, request);
  if (!override_basis) internal::LeaveOutUnmeasuredTools(nominal, data, &result.parameterization);
  if (options.gravity_tilt) {
    CHECK(!override_basis) << "a gravity tilt with a parameterization override";
    if (Status s = internal::AddSolverGravityTilt(options.gravity_tilt, &result.parameterization);
        !s.ok()) {
      return finish(Termination::kNotIdentifiable, s.message());
    }
  }
  const Parameterization& p = result.parameterization;
  const bool full = !override_basis && options.parameterization == ParameterizationKind::kFull;
  // Unknowns the data must determine: the identifiable count, whichever parameterization is solved.
  int gauge = 0;  // the frames' unidentifiable directions solved anyway (full parameterization)
  for (const Direction& d : p.unidentifiable) {  // those still in the basis (not left out)
    gauge += full && d.joint_block < 0 && p.basis[d.frame].cols() > 0 &&
             (p.basis[d.frame].transpose() * d.vector).norm() > 0.5;
  }
  const int identifiable = p.num_parameters - gauge;
  const int per_row = options.use_orientation ? 6 : 3;
  const long equations = static_cast<long>(per_row) * data.size();
  // The prior (lpoe/prior.h): identifiable parameterization only. Its reference is fixed here (the
  // start model unless given), so that the warm start's sub-solve keeps it.
  std::shared_ptr<const ParameterPrior> anchored;
  internal::ResolvedPrior prior;
  if (options.prior && !full) {
    if (options.prior->reference) {
      anchored = options.prior;
    } else {
      auto copy = std::make_shared<ParameterPrior>(*options.prior);
      copy->reference = std::make_shared<const RobotModel>(nominal);
      anchored = copy;
    }
    prior = internal::ResolvePrior(*anchored, nominal, data, p);
  }
  const bool use_prior = prior.active;
  if (equations < identifiable && !(use_prior && prior.informative)) {
    return finish(Termination::kNotIdentifiable,
                  internal::TooFewEquationsMessage(data.size(), equations, identifiable, per_row));
  }

  const bool stack = full;
  RobotModel model = nominal;
  const RobotModel& structure =
      options.structure_reference ? *options.structure_reference : nominal;
  // The joint-space blocks' coordinates (they start at zero: no joint error).
  const int K = p.num_joint_parameters();
  Eigen::VectorXd joint_state = internal::InitialJointState(p, options.initial_joint_terms);
  // The rows' joint regressors do not change during the solve: evaluated once. The full
  // parameterization (stacked rows) and a gravity tilt's solve (bilinear columns, gravity_tilt.h)
  // take the dense joint columns (JointRegressorRows); otherwise the normal equations are formed by
  // the joint blocks' structure (normal_equations.h).
  const bool structured = K > 0 && !stack && !p.gravity_tilt;
  const Eigen::MatrixXd joint_rows =
      structured ? Eigen::MatrixXd() : internal::JointRegressorRows(p, data);
  if (structured) internal::SetSlotBasis(p, &regressors);
  // The solve's linearizations: with every block exact, without the rows' errors, or with the joint
  // blocks left out (the structured iterations' frozen blocks).
  internal::NormalEquationsOptions exact_rows = RowsOf(options);
  exact_rows.stack = stack;
  exact_rows.joint_rows = &joint_rows;
  exact_rows.errors = errors;
  exact_rows.joint.regressors = &regressors;
  internal::NormalEquationsOptions exact_no_errors = exact_rows;
  exact_no_errors.errors = nullptr;
  internal::NormalEquationsOptions gradient_only = exact_rows;
  gradient_only.joint.gradient_only = true;
  auto joint_values = [&]() {
    Eigen::VectorXd x = Eigen::VectorXd::Zero(p.num_parameters);
    x.tail(K) = joint_state;
    return JointValuesOf(p, x);
  };
  Linearization lin =
      structured && joint_state.isZero() && internal::SameFrameDirections(analysed_p, p)
          ? internal::ProjectJointBlocks(analysed, p)
          : internal::NormalEquationsOf(model, data, p, joint_state, exact_rows);
  errors_current = errors != nullptr && !errors->empty();
  if (errors_current && options.errors->want_start_statistics && lin.finite) {
    options.errors->start_statistics = errors->Statistics();
    options.errors->have_start_statistics = true;
  }
  if (!lin.finite) {
    return finish(Termination::kNumericalFailure,
                  "non-finite residuals or Jacobian at the nominal model (check the input values)");
  }
  result.history.push_back(Record(0, lin));

  result.joint_terms = joint_values();  // zero until solved

  // The prior's rows at the current point and the data variance s2 they are weighted with (that of
  // the current point's residuals unless the prior fixes it): the step solves the data's normal
  // equations plus s2 A^T A, the cost compared is the data's plus s2 times the prior's.
  const long dof_all = equations - identifiable;
  auto prior_at = [&](const RobotModel& m, const Eigen::VectorXd& js) {
    return use_prior ? internal::LinearizePrior(prior, p, m, js) : internal::PriorRows();
  };
  internal::PriorRows prior_rows = prior_at(model, joint_state);
  double s2 = use_prior ? internal::PriorDataVariance(prior, lin.cost, dof_all) : 0.0;
  auto with_prior = [&](const Linearization& l, const internal::PriorRows& pr) {
    Linearization c;
    c.H = l.H;
    c.g = l.g;
    c.cost = l.cost;
    c.finite = l.finite;
    internal::AddPrior(pr, s2, &c.H, &c.g);
    return c;
  };
  auto total = [&](const Linearization& l, const internal::PriorRows& pr) {
    return l.cost + s2 * pr.cost();
  };

  // Identifiability in the calibrated directions, at the nominal model. For the full
  // parameterization this is analyzed in the identifiable basis (the full J^T J is singular by
  // construction).
  auto analyze = [&](const RobotModel& at, const Linearization& l, bool weakest) {
    if (!full) return Analyze(l.H, weakest);
    Parameterization pi = MakeParameterization(at, ParameterizationKind::kIdentifiable, kind);
    internal::LeaveOutStructurallyUnidentifiable(structure, data, options.use_orientation,
                                                 options.orientation_weight, &pi);
    CopyJointBlocks(p, &pi);
    internal::LeaveOutUnmeasuredTools(at, data, &pi);
    return Analyze(internal::NormalEquationsOf(at, data, pi, joint_state, RowsOf(options)).H,
                   weakest);
  };
  {
    // The eigenvalues decide; the weakest direction is computed only for the refusal's message.
    Identifiability id = use_prior && prior.informative
                             ? analyze(model, with_prior(lin, prior_rows), false)
                             : analyze(model, lin, false);
    result.rank = id.rank;
    result.condition_number = id.condition;
    result.singular_values = id.singular_values;
    if (id.rank < identifiable || !(id.condition <= options.max_condition_number)) {
      id = use_prior && prior.informative ? analyze(model, with_prior(lin, prior_rows), true)
                                          : analyze(model, lin, true);
      Parameterization pi = p;
      if (full) {
        pi = MakeParameterization(nominal, ParameterizationKind::kIdentifiable, kind);
        internal::LeaveOutStructurallyUnidentifiable(structure, data, options.use_orientation,
                                                     options.orientation_weight, &pi);
        CopyJointBlocks(p, &pi);
        internal::LeaveOutUnmeasuredTools(nominal, data, &pi);
      }
      return finish(Termination::kNotIdentifiable,
                    internal::NotIdentifiableMessage(id, identifiable,
                                                     options.max_condition_number, pi));
    }
  }

  // Frozen joint blocks (structured path): the joint-space columns J_q(q_eff) R change with the
  // geometry and the terms by about their relative size (1e-3), so the iterations form the frames'
  // block, the gradient and the cost exactly and keep the joint blocks of H (frames x joint,
  // joint x joint) from the last exact linearization: the step solves the exact gradient with a
  // slightly older H, which converges to the same solution (where the gradient is zero) with a
  // contraction of about that relative change per iteration. When the steps stop shrinking by
  // kFrozenContraction the blocks are formed again at the current point, and the covariance is
  // always computed from exact ones.
  constexpr double kFrozenContraction = 0.05;
  Eigen::MatrixXd frozen;  // P x K: H's joint columns
  auto freeze = [&](const Linearization& l) { frozen = l.H.rightCols(K); };
  auto complete = [&](Linearization* l) {
    l->H.rightCols(K) = frozen;
    l->H.bottomLeftCorner(K, p.num_parameters - K) = frozen.topRows(p.num_parameters - K).transpose();
  };
  auto exact = [&]() {
    Linearization l = internal::NormalEquationsOf(model, data, p, joint_state, exact_no_errors);
    freeze(l);
    return l;
  };
  if (structured) freeze(lin);

  // The warm start: at the first iteration the step x computed on all rows at the start model is
  // taken, and the solve continues on every `every`-th row (kept in order) to its own convergence;
  // all rows are then linearized at that solution (its errors, when kept, replace the start's),
  // which must not raise the cost of the start model. Records the subsample's iterations (with
  // their row count) and the new linearization's; returns the number of subsample iterations
  // recorded, or -1 when the warm start did not apply (then nothing changed but the kept errors,
  // no longer current: the caller continues as without it).
  const bool warm_start = !full && !override_basis && options.joint_terms.empty() &&
                          !options.gravity_tilt && K == 0 && options.warm_start_rows > 0 &&
                          data.size() >= options.warm_start_min_rows &&
                          data.size() >= 2 * options.warm_start_rows;
  auto WarmStart = [&](const Eigen::VectorXd& x, Linearization* current,
                       RobotModel* current_model) -> int {
    if (!x.allFinite()) return -1;
    const int every = (data.size() + options.warm_start_rows - 1) / options.warm_start_rows;
    std::vector<int> rows;
    rows.reserve(data.size() / every + 1);
    for (int r = 0; r < data.size(); r += every) rows.push_back(r);
    const MeasurementSet subset = data.Subset(rows);
    RobotModel first = *current_model;
    ApplyUpdate(p, x, &first);
    LinearSolverOptions sub = options;
    sub.parameterization_override = &p;  // the same directions (and no warm start of its own)
    sub.structure_reference = nullptr;
    sub.compute_covariance = false;
    sub.verbose = false;
    sub.on_iteration = nullptr;
    sub.errors = nullptr;
    sub.max_iterations = std::max(1, options.max_iterations - 2);
    sub.prior = anchored;
    const CalibrationResult s = CalibrateLinear(first, subset, sub);
    if (!s.converged() || s.history.empty()) return -1;
    Linearization at = internal::NormalEquationsOf(s.model, data, p, joint_state, exact_rows);
    errors_current = false;
    const internal::PriorRows at_prior = prior_at(s.model, joint_state);
    if (!at.finite || !(total(at, at_prior) <= total(*current, prior_rows) *
                                                   (1 + kCostIncreaseTolerance) +
                                               1e-300)) {
      return -1;
    }
    prior_rows = at_prior;
    errors_current = errors != nullptr && !errors->empty();
    result.history.back().step_norm = x.norm();
    // The subsample's records but its last (the point linearized on all rows now).
    const int taken = static_cast<int>(s.history.size()) - 1;
    for (int k = 0; k < taken; ++k) {
      IterationRecord r = s.history[k];
      r.iteration = 1 + k;
      r.rows = subset.size();
      result.history.push_back(r);
      if (options.on_iteration) options.on_iteration(r);
    }
    result.warm_start_rows = subset.size();
    *current_model = s.model;
    *current = std::move(at);
    result.history.push_back(Record(1 + taken, *current));
    if (options.on_iteration) options.on_iteration(result.history.back());
    return taken;
  };

  ConvergenceOptions stop = options.convergence;
  stop.step_tolerance = options.step_tolerance;
  const long dof = static_cast<long>(per_row) * data.size() - identifiable;
  double previous_cost = -1;
  double previous_step = -1;
  for (int it = 1; it <= options.max_iterations; ++it) {
    // The step's factorization also gives the stopping rule's standard deviations.
    Eigen::LLT<Eigen::MatrixXd> factor;
    Eigen::VectorXd scale;
    if (use_prior) {
      s2 = internal::PriorStepDataVariance(prior, lin.H, lin.g, lin.cost, prior_rows, dof_all);
    }
    Eigen::VectorXd x = use_prior
                            ? SolveStep(with_prior(lin, prior_rows), full, identifiable, options,
                                        &factor, &scale)
                            : SolveStep(lin, full, identifiable, options, &factor, &scale);
    if (structured && !lin.joint_blocks &&
        (!x.allFinite() || (previous_step >= 0 && x.norm() > kFrozenContraction * previous_step))) {
      lin = exact();
      scale.resize(0);
      x = use_prior ? SolveStep(with_prior(lin, prior_rows), full, identifiable, options, &factor,
                                &scale)
                    : SolveStep(lin, full, identifiable, options, &factor, &scale);
    }
    previous_step = x.norm();
    if (!x.allFinite()) {
      return finish(Termination::kNumericalFailure,
                    "the least-squares step is not finite (numerically singular normal equations)");
    }
    const double step = x.norm();
    result.history.back().step_norm = step;
    if (options.verbose) {
      LOG(INFO) << "iteration " << it - 1 << ": max " << lin.max_error << " mm, mean "
                << lin.mean_error << " mm, |x| " << step;
    }
    ConvergenceState state;
    state.step = x;
    if (!full) {
      state.standard_deviation =
          scale.size() == lin.H.rows()
              ? StandardDeviationsFromFactor(factor.matrixLLT(), scale, lin.cost, dof)
              : StandardDeviations(use_prior ? with_prior(lin, prior_rows).H : lin.H, lin.cost,
                                   dof);
    }
    state.parameter_scale = ParameterScale(model);
    state.cost = use_prior ? total(lin, prior_rows) : lin.cost;
    state.previous_cost = previous_cost;
    const ConvergenceDecision decision = TestConvergence(stop, state);
    if (decision.converged()) {
      if (structured && !lin.joint_blocks) {
        // With frozen joint blocks the contraction per step is about their relative change, not
        // quadratic: the last (tiny) step is taken too, and the solution's normal equations are
        // formed exactly (the covariance's, and the final cost).
        RobotModel candidate = model;
        ApplyUpdate(p, x, &candidate);
        const Eigen::VectorXd candidate_joints = joint_state + x.tail(K);
        const RobotModel kept_model = model;
        const Eigen::VectorXd kept_joints = joint_state;
        model = std::move(candidate);
        joint_state = candidate_joints;
        Linearization last = exact();
        const internal::PriorRows last_prior = prior_at(model, joint_state);
        if (last.finite && total(last, last_prior) <=
                               total(lin, prior_rows) * (1 + kCostIncreaseTolerance) + 1e-300) {
          lin = std::move(last);
          prior_rows = last_prior;
        } else {
          model = kept_model;
          joint_state = kept_joints;
          lin = exact();
        }
      }
      result.stop_rule = decision.rule;
      result.model = model;
      result.joint_terms = joint_values();
      result.iterations = it - 1;
      result.final_cost = lin.cost;
      if (use_prior) {
        // What the prior contributed (at the solution's residuals) and the posterior covariance.
        s2 = internal::PriorDataVariance(prior, lin.cost, dof_all);
        result.prior_data_sigma = std::sqrt(s2);
        result.prior_cost = s2 * prior_rows.cost();
        internal::PriorContribution(prior_rows, lin.H, s2, &result.prior_standard_deviation,
                                    &result.data_share);
      }
      if (options.compute_covariance && !full) {
        if (dof > 0) {
          const double s2_post = 2.0 * lin.cost / static_cast<double>(dof);
          const Eigen::MatrixXd Hc = use_prior ? with_prior(lin, prior_rows).H : lin.H;
          const Eigen::VectorXd d = ColumnScale(Hc);
          const Eigen::MatrixXd Hs = d.asDiagonal() * Hc * d.asDiagonal();
          const Eigen::LLT<Eigen::MatrixXd> llt(Hs);
          if (llt.info() == Eigen::Success) {
            const Eigen::MatrixXd inv = InverseFromCholeskyFactor(llt.matrixLLT());
            result.covariance = s2_post * (d.asDiagonal() * inv * d.asDiagonal());
          }
        }
      }
      internal::FillGravityTiltResult(p, joint_state, result.covariance, &result.gravity_tilt);
      return finish(Termination::kConverged, decision.message);
    }
    // Warm start (large data, linear_solver.h): the iterations that cross the model's large
    // initial errors run on a subsample; all rows are linearized again only at its solution.
    if (it == 1 && warm_start) {
      const int taken = WarmStart(x, &lin, &model);
      if (taken >= 0) {
        previous_cost = result.history.front().cost;
        previous_step = -1;
        it += taken;  // the subsample's iterations; the next one is on all rows
        continue;
      }
    }
    // Gauss-Newton step with backtracking: a step that raises the cost is halved.
    bool accepted = false;
    double alpha = 1.0;
    for (int h = 0; h <= kMaxHalvings && !accepted; ++h, alpha *= 0.5) {
      RobotModel candidate = model;
      ApplyUpdate(p, alpha * x, &candidate);
      const Eigen::VectorXd candidate_joints = joint_state + alpha * x.tail(K);
      Linearization next = internal::NormalEquationsOf(candidate, data, p, candidate_joints,
                                                       structured ? gradient_only : exact_rows);
      errors_current = false;
      if (structured) complete(&next);
      const internal::PriorRows next_prior = prior_at(candidate, candidate_joints);
      if (next.finite && total(next, next_prior) <=
                             total(lin, prior_rows) * (1 + kCostIncreaseTolerance) + 1e-300) {
        errors_current = errors != nullptr && !errors->empty();
        model = std::move(candidate);
        joint_state = candidate_joints;
        previous_cost = total(lin, prior_rows);
        lin = std::move(next);
        prior_rows = next_prior;
        accepted = true;
      }
    }
    if (!accepted) {
      result.model = model;
      result.joint_terms = joint_values();
      internal::FillGravityTiltResult(p, joint_state, Eigen::MatrixXd(), &result.gravity_tilt);
      result.iterations = it - 1;
      result.final_cost = lin.cost;
      std::ostringstream os;
      os << "no step along the least-squares direction reduces the cost (|x| = " << step
         << "); the linearization is not valid here (check units, angle_unit and the base frame)";
      return finish(Termination::kNumericalFailure, os.str());
    }
    result.history.push_back(Record(it, lin));
    if (options.on_iteration) options.on_iteration(result.history.back());
  }
  result.model = model;
  result.joint_terms = joint_values();
  internal::FillGravityTiltResult(p, joint_state, Eigen::MatrixXd(), &result.gravity_tilt);
  result.iterations = options.max_iterations;
  result.final_cost = lin.cost;
  std::ostringstream os;
  os << "not converged after " << options.max_iterations << " iterations (last |x| = "
     << result.history[result.history.size() - 2].step_norm << ", tolerance "
     << options.step_tolerance << ")";
  return finish(Termination::kMaxIterations, os.str());
}

}  // namespace lpoe
