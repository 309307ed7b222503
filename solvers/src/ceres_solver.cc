#include "lpoe/ceres_solver.h"

#include <array>
#include <chrono>
#include <cmath>
#include <memory>
#include <sstream>
#include <utility>
#include <vector>

#include <ceres/ceres.h>
#include <glog/logging.h>

#include "identifiability.h"
#include "lpoe/measurement_residual.h"
#include "lpoe/se3_manifold.h"
#include "structural_identifiability.h"

namespace lpoe {
namespace {

using Block = std::array<double, kSe3AmbientSize>;

bool ParseLinearSolver(const std::string& name, ceres::LinearSolverType* type) {
  return ceres::StringToLinearSolverType(name, type);
}

// The frames of `model` replaced by the parameter blocks that exist (the others keep theirs).
RobotModel ModelFromBlocks(const RobotModel& base, const std::vector<Block>& blocks,
                           const std::vector<bool>& used) {
  RobotModel model = base;
  const int n = model.num_joints();
  for (int f = 0; f < model.num_frames(); ++f) {
    if (!used[f]) continue;
    SE3d& T = f < n ? model.joints[f].origin : model.tools[f - n].origin;
    T = Se3FromArray(blocks[f].data());
  }
  return model;
}

// The joint-space terms' values from their parameter blocks (x_b, k_b numbers each).
std::vector<JointTermValues> JointValuesFromBlocks(const Parameterization& p,
                                                   const std::vector<std::vector<double>>& x) {
  Eigen::VectorXd all = Eigen::VectorXd::Zero(p.num_parameters);
  for (size_t b = 0; b < p.joint_blocks.size(); ++b) {
    const JointBlock& block = p.joint_blocks[b];
    for (int c = 0; c < block.basis.cols(); ++c) all(block.offset + c) = x[b][c];
  }
  return JointValuesOf(p, all);
}
// The stopping rules of convergence.h on Ceres's accepted steps: the step is the difference of the
// models before and after it in the solved directions, the standard deviations come from J^T J at
// the start (`H`, solved columns only; empty: unknown) and the current cost.
struct ConvergenceWatch {
  ConvergenceOptions options;
  const Parameterization* p = nullptr;
  std::vector<int> columns;  // solved parameters (used frames) in p's order
  Eigen::MatrixXd H;
  long dof = 0;
  ConvergenceDecision decision;

  bool Stop(const RobotModel& before, const RobotModel& after, double cost, double previous_cost) {
    const Eigen::VectorXd all = ParameterDifference(*p, before, after);
    ConvergenceState state;
    state.step.resize(static_cast<Eigen::Index>(columns.size()));
    for (size_t k = 0; k < columns.size(); ++k) state.step(k) = all(columns[k]);
    if (H.size() > 0) state.standard_deviation = StandardDeviations(H, cost, dof);
    state.parameter_scale = ParameterScale(after);
    state.cost = cost;
    state.previous_cost = previous_cost;
    decision = TestConvergence(options, state);
    return decision.converged();
  }
};

// Records the history (IterationRecord per accepted step) with the state of the blocks, which Ceres
// updates every iteration (update_state_every_iteration).
class HistoryCallback : public ceres::IterationCallback {
 public:
  HistoryCallback(const RobotModel& base, const MeasurementSet& data, const Parameterization& p,
                  const std::vector<Block>& blocks, const std::vector<bool>& used,
                  const std::vector<std::vector<double>>& joint_blocks, double cost_scale,
                  std::vector<IterationRecord>* history,
                  std::function<void(const IterationRecord&)> on_iteration,
                  ConvergenceWatch* watch)
      : watch_(watch),
        previous_(base),
        base_(base),
        data_(data),
        p_(p),
        blocks_(blocks),
        used_(used),
        joint_blocks_(joint_blocks),
        cost_scale_(cost_scale),
        history_(history),
        on_iteration_(std::move(on_iteration)) {}

  ceres::CallbackReturnType operator()(const ceres::IterationSummary& summary) override {
    if (summary.iteration > 0 && !summary.step_is_successful) return ceres::SOLVER_CONTINUE;
    RobotModel model = ModelFromBlocks(base_, blocks_, used_);
    const ErrorStatistics stats =
        p_.joint_blocks.empty()
            ? PositionErrorStatistics(model, data_)
            : PositionErrorStatistics(
                  model,
                  WithEffectiveJointValues(JointValuesFromBlocks(p_, joint_blocks_), data_));
    IterationRecord r;
    r.iteration = summary.iteration;
    r.cost = summary.cost * cost_scale_;
    r.max_error = stats.norm.max_abs;
    r.mean_error = stats.norm.mean_abs;
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
  const RobotModel& base_;
  const MeasurementSet& data_;
  const Parameterization& p_;
  const std::vector<Block>& blocks_;
  const std::vector<bool>& used_;
  const std::vector<std::vector<double>>& joint_blocks_;
  double cost_scale_;
  std::vector<IterationRecord>* history_;
  std::function<void(const IterationRecord&)> on_iteration_;
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
                         "' (dense_qr, dense_normal_cholesky, sparse_normal_cholesky, dense_schur, "
                         "sparse_schur, iterative_schur, cgnr)");
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
  if (options.loss != "none" && options.loss != "huber" && options.loss != "cauchy") {
    return Status::Error("loss must be none, huber or cauchy, got '" + options.loss + "'");
  }
  if (!(options.sigma > 0) || !std::isfinite(options.sigma)) {
    return Status::Error("sigma must be a positive number of mm");
  }
  if (!(options.loss_scale > 0) || !std::isfinite(options.loss_scale)) {
    return Status::Error("loss_scale must be a positive number of mm");
  }
  if (!(options.orientation_weight > 0) || !std::isfinite(options.orientation_weight)) {
    return Status::Error("orientation_weight must be positive");
  }
  if (options.max_iterations < 1) return Status::Error("max_iterations must be >= 1");
  if (options.num_threads < 1) return Status::Error("num_threads must be >= 1");
  if (const std::string e = ValidateConvergenceOptions(options.convergence); !e.empty()) {
    return Status::Error(e);
  }
  return Status::Ok();
}

CalibrationResult CalibrateCeres(const RobotModel& nominal, const MeasurementSet& data,
                                 const CeresSolverOptions& options) {
  const auto start = std::chrono::steady_clock::now();
  CalibrationResult result;
  result.model = nominal;
  auto finish = [&](Termination t, const std::string& message) {
    result.termination = t;
    result.message = message;
    result.wall_time_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return result;
  };

  {
    const Status s = ValidateCeresSolverOptions(options);
    CHECK(s.ok()) << s.message();
  }
  CHECK_EQ(data.num_joints(), nominal.num_joints()) << "measurements do not match the model";
  for (int r = 0; r < data.size(); ++r) {
    CHECK(data.target(r) >= 0 && data.target(r) < nominal.num_tools()) << "bad target in row " << r;
  }
  if (options.use_orientation && !data.has_orientation()) {
    return finish(Termination::kNotIdentifiable,
                  "pose-based calibration needs measured orientations (quat_x..quat_w columns)");
  }
  const DataKind kind = options.use_orientation ? DataKind::kPose : DataKind::kPosition;
  const bool full = options.parameterization == ParameterizationKind::kFull;
  result.parameterization = internal::SolverParameterization(
      nominal, data, options.parameterization, options.use_orientation, options.orientation_weight,
      options.joint_terms, options.joint_term_tolerance, options.structure_reference);
  internal::LeaveOutUnmeasuredTools(nominal, data, &result.parameterization);
  const Parameterization& p = result.parameterization;
  const int per_row = options.use_orientation ? 6 : 3;
  int identifiable = 0;  // parameters the data must determine (identifiable directions, used frames)

  ConvergenceWatch watch;
  watch.options = options.convergence;

  // ---- Parameter blocks: every joint frame, and the tools that some row measures.
  const int n = nominal.num_joints();
  const int F = nominal.num_frames();
  std::vector<Block> blocks(F);
  std::vector<bool> used(F, false);
  for (int f = 0; f < F; ++f) {
    Se3ToArray(f < n ? nominal.joints[f].origin : nominal.tools[f - n].origin, blocks[f].data());
  }
  for (int i = 0; i < n; ++i) used[i] = true;
  for (int r = 0; r < data.size(); ++r) used[n + data.target(r)] = true;
  // One block per joint-space term (x_b, starting at zero); blocks with nothing identifiable left
  // are not in the problem.
  const int num_joint_blocks = static_cast<int>(p.joint_blocks.size());
  std::vector<std::vector<double>> joint_blocks(num_joint_blocks);
  std::vector<int> solved_joint_blocks;
  for (int b = 0; b < num_joint_blocks; ++b) {
    joint_blocks[b].assign(p.joint_blocks[b].basis.cols(), 0.0);
    if (!joint_blocks[b].empty()) solved_joint_blocks.push_back(b);
  }
  result.joint_terms = JointValuesFromBlocks(p, joint_blocks);

  // ---- The identifiability check of the linear solver (same thresholds, same messages), on the
  // identifiable directions of the frames that are solved (unmeasured tools are not).
  {
    Parameterization all = p;
    if (full) {
      all = MakeParameterization(nominal, ParameterizationKind::kIdentifiable, kind);
      internal::LeaveOutStructurallyUnidentifiable(
          options.structure_reference ? *options.structure_reference : nominal, data,
          options.use_orientation, options.orientation_weight, &all);
      CopyJointBlocks(p, &all);
    }
    Parameterization solved;  // the directions of the used frames, for the message
    std::vector<int> columns;
    for (int f = 0; f < F; ++f) {
      if (!used[f]) continue;
      for (int c = 0; c < all.basis[f].cols(); ++c) {
        columns.push_back(all.offset[f] + c);
        solved.parameters.push_back(all.parameters[all.offset[f] + c]);
      }
    }
    for (int k = all.num_frame_parameters(); k < all.num_parameters; ++k) {
      columns.push_back(k);
      solved.parameters.push_back(all.parameters[k]);
    }
    solved.num_parameters = static_cast<int>(columns.size());
    identifiable = solved.num_parameters;
    const long equations = static_cast<long>(per_row) * data.size();
    if (equations < identifiable) {
      return finish(Termination::kNotIdentifiable,
                    internal::TooFewEquationsMessage(data.size(), equations, identifiable, per_row));
    }
    const Eigen::MatrixXd H_all = internal::NormalMatrix(nominal, data, all, options.use_orientation,
                                                         options.orientation_weight);
    Eigen::MatrixXd H(identifiable, identifiable);
    for (int a = 0; a < identifiable; ++a) {
      for (int b = 0; b < identifiable; ++b) H(a, b) = H_all(columns[a], columns[b]);
    }
    if (!H.allFinite()) {
      return finish(Termination::kNumericalFailure,
                    "non-finite residuals or Jacobian at the nominal model (check the input values)");
    }
    watch.p = &result.parameterization;
    watch.columns = columns;
    if (full) {  // the step is measured in p's (full) coordinates of the solved frames
      watch.columns.clear();
      for (int f = 0; f < F; ++f) {
        for (int c = 0; used[f] && c < p.basis[f].cols(); ++c) watch.columns.push_back(p.offset[f] + c);
      }
    }
    watch.dof = static_cast<long>(per_row) * data.size() - identifiable;
    if (!full) watch.H = H;
    const internal::Identifiability id = internal::Analyze(H);
    result.rank = id.rank;
    result.condition_number = id.condition;
    result.singular_values = id.singular_values;
    if (id.rank < identifiable || !(id.condition <= options.max_condition_number)) {
      return finish(Termination::kNotIdentifiable,
                    internal::NotIdentifiableMessage(id, identifiable,
                                                     options.max_condition_number, solved));
    }
  }

  ceres::Problem problem;
  ceres::LossFunction* loss = nullptr;  // shared by all residual blocks; owned by the problem
  const double whitened_scale = options.loss_scale / options.sigma;
  if (options.loss == "huber") loss = new ceres::HuberLoss(whitened_scale);
  if (options.loss == "cauchy") loss = new ceres::CauchyLoss(whitened_scale);

  const auto shared_model = std::make_shared<const RobotModel>(nominal);
  std::vector<double*> parameters(n + 1);
  for (int i = 0; i < n; ++i) parameters[i] = blocks[i].data();
  std::vector<int> block_sizes;
  int K = 0;
  for (int b : solved_joint_blocks) {
    parameters.push_back(joint_blocks[b].data());
    block_sizes.push_back(static_cast<int>(joint_blocks[b].size()));
    K += block_sizes.back();
  }
  PositionMeasurement position_kind;
  position_kind.inverse_sigma = 1.0 / options.sigma;
  PoseMeasurement pose_kind;
  pose_kind.inverse_sigma = 1.0 / options.sigma;
  pose_kind.orientation_weight = options.orientation_weight;
  Eigen::MatrixXd term_Y;
  for (int r = 0; r < data.size(); ++r) {
    parameters[n] = blocks[n + data.target(r)].data();
    // This row's joint regressor [Y_b(q) basis_b] (data: evaluated once).
    Eigen::MatrixXd R(n, K);
    int column = 0;
    for (int b : solved_joint_blocks) {
      const JointBlock& block = p.joint_blocks[b];
      term_Y.resize(n, block.term->num_parameters());
      block.term->Regressor(data.q(r), term_Y.data());
      R.middleCols(column, block.basis.cols()) = term_Y * block.basis;
      column += static_cast<int>(block.basis.cols());
    }
    ceres::CostFunction* cost =
        options.use_orientation
            ? PoseResidual::Create(shared_model, pose_kind, data.q(r), data.pose(r), R, block_sizes)
            : PositionResidual::Create(shared_model, position_kind, data.q(r), data.position(r),
                                       R, block_sizes);
    problem.AddResidualBlock(cost, loss, parameters);
  }
  std::vector<const double*> covariance_blocks;
  for (int f = 0; f < F; ++f) {
    if (!used[f]) continue;
    problem.SetManifold(blocks[f].data(), new Se3Manifold(p.basis[f]));
    covariance_blocks.push_back(blocks[f].data());
    if (p.basis[f].cols() == 0) {  // every direction left out (structurally unidentifiable)
      problem.SetParameterBlockConstant(blocks[f].data());
      continue;
    }
  }
  for (int b : solved_joint_blocks) covariance_blocks.push_back(joint_blocks[b].data());

  // ---- Solve.
  ceres::Solver::Options solver_options;
  CHECK(ParseLinearSolver(options.linear_solver, &solver_options.linear_solver_type));
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
  const double cost_scale = options.sigma * options.sigma;
  HistoryCallback callback(nominal, data, p, blocks, used, joint_blocks, cost_scale,
                           &result.history, options.on_iteration, &watch);
  solver_options.callbacks.push_back(&callback);

  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);
  if (options.verbose) LOG(INFO) << summary.FullReport();

  result.model = ModelFromBlocks(nominal, blocks, used);
  result.joint_terms = JointValuesFromBlocks(p, joint_blocks);
  result.iterations = summary.num_successful_steps + summary.num_unsuccessful_steps;
  result.final_cost = summary.final_cost * cost_scale;
  const Termination termination = MapTermination(summary.termination_type);
  std::string message = "ceres: " + summary.message;
  if (summary.termination_type == ceres::USER_SUCCESS && watch.decision.converged()) {
    result.stop_rule = watch.decision.rule;
    message = "ceres: " + watch.decision.message;
  }
  if (termination == Termination::kNumericalFailure) {
    return finish(termination, message);
  }

  // ---- Covariance in the tangent spaces, in the parameterization's order.
  if (options.compute_covariance && termination == Termination::kConverged) {
    ceres::Covariance::Options cov_options;
    cov_options.algorithm_type = ceres::DENSE_SVD;
    cov_options.num_threads = options.num_threads;
    // Full parameterization: the gauge directions are a known null space; take the
    // pseudo-inverse (singular values below min_reciprocal_condition_number are dropped).
    cov_options.null_space_rank = full ? -1 : 0;
    ceres::Covariance covariance(cov_options);
    std::vector<std::pair<const double*, const double*>> pairs;
    for (const double* a : covariance_blocks) pairs.emplace_back(a, a);
    int tangent = K;
    for (int f = 0; f < F; ++f) tangent += used[f] ? static_cast<int>(p.basis[f].cols()) : 0;
    Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> C(tangent, tangent);
    if (covariance.Compute(covariance_blocks, &problem) &&
        covariance.GetCovarianceMatrixInTangentSpace(covariance_blocks, C.data())) {
      result.covariance = Eigen::MatrixXd::Zero(p.num_parameters, p.num_parameters);
      // Rows of C follow covariance_blocks (used frames, then joint blocks, in order); scatter
      // to p's offsets.
      std::vector<int> c_offset, p_offset, size;
      int at = 0;
      auto add = [&](int offset, int k) {
        c_offset.push_back(at);
        p_offset.push_back(offset);
        size.push_back(k);
        at += k;
      };
      for (int f = 0; f < F; ++f) {
        if (used[f] && p.basis[f].cols() > 0) add(p.offset[f], static_cast<int>(p.basis[f].cols()));
      }
      for (int b : solved_joint_blocks) {
        add(p.joint_blocks[b].offset, static_cast<int>(p.joint_blocks[b].basis.cols()));
      }
      for (size_t a = 0; a < size.size(); ++a) {
        for (size_t b = 0; b < size.size(); ++b) {
          result.covariance.block(p_offset[a], p_offset[b], size[a], size[b]) =
              C.block(c_offset[a], c_offset[b], size[a], size[b]);
        }
      }
      if (options.a_posteriori_covariance) {
        const long dof = static_cast<long>(per_row) * data.size() - identifiable;
        if (dof > 0) result.covariance *= 2.0 * summary.final_cost / static_cast<double>(dof);
      }
    } else {
      message += "; covariance not computed (rank-deficient Jacobian at the solution)";
    }
  }
  return finish(termination, message);
}

}  // namespace lpoe
