#include "lpoe/linear_solver.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <sstream>
#include <thread>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <glog/logging.h>

#include "identifiability.h"
#include "lpoe/kinematics.h"

namespace lpoe {
namespace {

// Step halvings tried when a Gauss-Newton step raises the cost.
constexpr int kMaxHalvings = 12;
// A step is accepted if it does not raise the cost by more than this relative amount (round-off).
constexpr double kCostIncreaseTolerance = 1e-10;

using Linearization = internal::NormalEquations;

// Poses per block of stacked rows handed to one symmetric rank-k update (H += A^T A, a blocked
// SYRK): large enough to amortize Eigen's packing, small enough to stay in L1/L2.
constexpr int kBlockPoses = 64;
// The rows are cut into at most kMaxChunks contiguous chunks of at least kMinChunkPoses poses, a
// partition that depends on the row count only. Each chunk accumulates its own partial sums; they
// are added in chunk order. So the result is bit-identical whatever the number of threads and
// whichever thread takes which chunk.
constexpr int kMaxChunks = 64;
constexpr int kMinChunkPoses = 1024;
// Below this many poses everything runs on the calling thread.
constexpr int kMinPosesForThreads = 2000;

// Partial sums of one chunk of rows.
struct ChunkSums {
  Eigen::MatrixXd H;  // lower triangle
  Eigen::VectorXd g;
  double cost = 0;
  double max_error = 0;
  double sum_error = 0;
};

// Per-thread scratch (allocated once per thread and Linearize call, never per row).
struct Scratch {
  Eigen::MatrixXd A;  // m * kBlockPoses x P stacked Jacobian rows
  Eigen::VectorXd Y;  // m * kBlockPoses residuals
  std::vector<FrameRt> frames;
};

// Accumulates rows [begin, end) into `sums` (and into the stacked J and y when `lin` stacks).
void AccumulateRows(const BasisJacobian& bj, const MeasurementSet& data, bool use_orientation,
                    double orientation_weight, int begin, int end, Scratch* scratch,
                    ChunkSums* sums, Linearization* stacked) {
  const int m = use_orientation ? 6 : 3;
  const int P = bj.num_parameters();
  const int ld = m * kBlockPoses;
  double* A = scratch->A.data();
  double* Y = scratch->Y.data();
  FrameRt* frames = scratch->frames.data();
  const double w = orientation_weight;
  for (int r0 = begin; r0 < end; r0 += kBlockPoses) {
    const int count = std::min(kBlockPoses, end - r0);
    for (int k = 0; k < count; ++k) {
      const int r = r0 + k;
      const double* q = data.q(r);
      const int tool = data.target(r);
      double* Jr = A + m * k;
      double* y = Y + m * k;
      double e_sq;
      if (use_orientation) {
        const SE3d T = bj.Pose(q, tool, Jr, ld, frames);
        Vector6d yr = LogSE3(data.pose(r) * T.Inverse());  // eq. (17)
        e_sq = (data.position(r) - T.t).squaredNorm();
        // Weight the rotation rows: 1 rad counts as orientation_weight mm.
        yr.head<3>() *= w;
        for (int c = 0; c < P; ++c) {
          double* col = Jr + static_cast<std::ptrdiff_t>(c) * ld;
          col[0] *= w;
          col[1] *= w;
          col[2] *= w;
        }
        for (int i = 0; i < 6; ++i) y[i] = yr(i);
        sums->cost += 0.5 * yr.squaredNorm();
      } else {
        const Eigen::Vector3d P_model = bj.Position(q, tool, Jr, ld, frames);
        const Eigen::Vector3d yr = data.position(r) - P_model;  // eq. (30)
        y[0] = yr(0);
        y[1] = yr(1);
        y[2] = yr(2);
        e_sq = yr.squaredNorm();
        sums->cost += 0.5 * e_sq;
      }
      const double e = std::sqrt(e_sq);
      sums->max_error = std::max(sums->max_error, e);
      sums->sum_error += e;
    }
    const int rows = m * count;
    const auto Ab = scratch->A.topRows(rows);
    sums->H.selfadjointView<Eigen::Lower>().rankUpdate(Ab.transpose());
    sums->g.noalias() += Ab.transpose() * scratch->Y.head(rows);
    if (stacked != nullptr) {
      stacked->J.middleRows(static_cast<Eigen::Index>(m) * r0, rows) = Ab;
      stacked->y.segment(static_cast<Eigen::Index>(m) * r0, rows) = scratch->Y.head(rows);
    }
  }
}

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
  *p = std::move(out);
}

NormalEquations NormalEquationsOf(const RobotModel& model, const MeasurementSet& data,
                                  const Parameterization& p, bool use_orientation,
                                  double orientation_weight, bool stack) {
  const int P = p.num_parameters;
  const int m = use_orientation ? 6 : 3;
  const int N = data.size();
  Linearization lin;
  lin.H.setZero(P, P);
  lin.g.setZero(P);
  if (stack) {
    lin.J.setZero(static_cast<Eigen::Index>(m) * N, P);
    lin.y.setZero(static_cast<Eigen::Index>(m) * N);
  }
  const BasisJacobian bj(model, p);

  const int chunks = std::max(1, std::min(kMaxChunks, N / kMinChunkPoses));
  const int chunk_size = N == 0 ? 0 : (N + chunks - 1) / chunks;
  std::vector<ChunkSums> sums(chunks);
  auto make_scratch = [&]() {
    Scratch s;
    s.A.resize(static_cast<Eigen::Index>(m) * kBlockPoses, P);
    s.Y.resize(static_cast<Eigen::Index>(m) * kBlockPoses);
    s.frames.resize(model.num_joints() + 1);
    return s;
  };
  auto run_chunk = [&](int c, Scratch* scratch) {
    ChunkSums& cs = sums[c];
    cs.H.setZero(P, P);
    cs.g.setZero(P);
    const int begin = std::min(N, c * chunk_size);
    const int end = std::min(N, begin + chunk_size);
    AccumulateRows(bj, data, use_orientation, orientation_weight, begin, end, scratch, &cs,
                   stack ? &lin : nullptr);
  };
  const int hardware = static_cast<int>(std::thread::hardware_concurrency());
  const int threads = N < kMinPosesForThreads ? 1 : std::max(1, std::min(hardware, chunks));
  if (threads == 1) {
    Scratch scratch = make_scratch();
    for (int c = 0; c < chunks; ++c) run_chunk(c, &scratch);
  } else {
    // Chunks are taken in any order; each writes only its own sums (and its own rows of J, y).
    std::atomic<int> next(0);
    auto worker = [&]() {
      Scratch scratch = make_scratch();
      for (int c = next.fetch_add(1); c < chunks; c = next.fetch_add(1)) run_chunk(c, &scratch);
    };
    std::vector<std::thread> pool;
    for (int t = 1; t < threads; ++t) pool.emplace_back(worker);
    worker();
    for (std::thread& t : pool) t.join();
  }
  // Fixed-order reduction.
  double sum_error = 0;
  for (const ChunkSums& cs : sums) {
    lin.H += cs.H;
    lin.g += cs.g;
    lin.cost += cs.cost;
    lin.max_error = std::max(lin.max_error, cs.max_error);
    sum_error += cs.sum_error;
  }
  lin.H.triangularView<Eigen::StrictlyUpper>() = lin.H.transpose();
  lin.mean_error = data.empty() ? 0.0 : sum_error / data.size();
  lin.finite = std::isfinite(lin.cost) && lin.H.allFinite() && lin.g.allFinite();
  return lin;
}

}  // namespace internal

namespace {

Linearization Linearize(const RobotModel& model, const MeasurementSet& data,
                        const Parameterization& p, const LinearSolverOptions& options,
                        bool stack) {
  return internal::NormalEquationsOf(model, data, p, options.use_orientation,
                                     options.orientation_weight, stack);
}

// The identifiability check shared with the Ceres solver (identifiability.h).
using internal::Analyze;
using internal::ColumnScale;
using internal::Identifiability;

// Least-squares step x of J x = y.
Eigen::VectorXd SolveStep(const Linearization& lin, bool full, const LinearSolverOptions& options) {
  const Eigen::VectorXd d = ColumnScale(lin.H);
  if (full) {
    // Minimum-norm solution of the rank-deficient system (the paper's eq. (32) read as a
    // pseudo-inverse), on the column-scaled stacked Jacobian for accuracy.
    const Eigen::MatrixXd Js = lin.J * d.asDiagonal();
    Eigen::BDCSVD<Eigen::MatrixXd> svd(Js, Eigen::ComputeThinU | Eigen::ComputeThinV);
    svd.setThreshold(options.pseudo_inverse_tolerance);
    // The minimum-norm solution in scaled coordinates; mapped back by d.
    return d.asDiagonal() * svd.solve(lin.y);
  }
  const Eigen::MatrixXd Hs = d.asDiagonal() * lin.H * d.asDiagonal();
  const Eigen::VectorXd gs = d.asDiagonal() * lin.g;
  Eigen::LLT<Eigen::MatrixXd> llt(Hs);
  if (llt.info() != Eigen::Success) return Eigen::VectorXd::Constant(lin.g.size(), NAN);
  return d.asDiagonal() * llt.solve(gs);
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
  auto finish = [&](Termination t, const std::string& message) {
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
  result.parameterization = override_basis
                                ? *options.parameterization_override
                                : MakeParameterization(nominal, options.parameterization, kind);
  const int gauge = static_cast<int>(result.parameterization.unidentifiable.size());
  if (!override_basis) internal::LeaveOutUnmeasuredTools(nominal, data, &result.parameterization);
  const Parameterization& p = result.parameterization;
  const bool full = !override_basis && options.parameterization == ParameterizationKind::kFull;
  // Unknowns the data must determine: the identifiable count, whichever parameterization is solved.
  const int identifiable = p.num_parameters - (full ? gauge : 0);
  const int per_row = options.use_orientation ? 6 : 3;
  const long equations = static_cast<long>(per_row) * data.size();
  if (equations < identifiable) {
    return finish(Termination::kNotIdentifiable,
                  internal::TooFewEquationsMessage(data.size(), equations, identifiable, per_row));
  }

  const bool stack = full;
  RobotModel model = nominal;
  Linearization lin = Linearize(model, data, p, options, stack);
  if (!lin.finite) {
    return finish(Termination::kNumericalFailure,
                  "non-finite residuals or Jacobian at the nominal model (check the input values)");
  }
  result.history.push_back(Record(0, lin));

  // Identifiability in the calibrated directions, at the nominal model. For the full
  // parameterization this is analyzed in the identifiable basis (the full J^T J is singular by
  // construction).
  auto analyze = [&](const RobotModel& at, const Linearization& l) {
    if (!full) return Analyze(l.H);
    LinearSolverOptions o = options;
    o.parameterization = ParameterizationKind::kIdentifiable;
    Parameterization pi = MakeParameterization(at, o.parameterization, kind);
    internal::LeaveOutUnmeasuredTools(at, data, &pi);
    return Analyze(Linearize(at, data, pi, o, false).H);
  };
  {
    const Identifiability id = analyze(model, lin);
    result.rank = id.rank;
    result.condition_number = id.condition;
    result.singular_values = id.singular_values;
    if (id.rank < identifiable || !(id.condition <= options.max_condition_number)) {
      Parameterization pi =
          full ? MakeParameterization(nominal, ParameterizationKind::kIdentifiable, kind) : p;
      if (full) internal::LeaveOutUnmeasuredTools(nominal, data, &pi);
      return finish(Termination::kNotIdentifiable,
                    internal::NotIdentifiableMessage(id, identifiable,
                                                     options.max_condition_number, pi));
    }
  }

  ConvergenceOptions stop = options.convergence;
  stop.step_tolerance = options.step_tolerance;
  const long dof = static_cast<long>(per_row) * data.size() - identifiable;
  double previous_cost = -1;
  for (int it = 1; it <= options.max_iterations; ++it) {
    const Eigen::VectorXd x = SolveStep(lin, full, options);
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
    if (!full) state.standard_deviation = StandardDeviations(lin.H, lin.cost, dof);
    state.parameter_scale = ParameterScale(model);
    state.cost = lin.cost;
    state.previous_cost = previous_cost;
    const ConvergenceDecision decision = TestConvergence(stop, state);
    if (decision.converged()) {
      result.stop_rule = decision.rule;
      result.model = model;
      result.iterations = it - 1;
      result.final_cost = lin.cost;
      if (options.compute_covariance && !full) {
        if (dof > 0) {
          const double s2 = 2.0 * lin.cost / static_cast<double>(dof);
          const Eigen::VectorXd d = ColumnScale(lin.H);
          const Eigen::MatrixXd Hs = d.asDiagonal() * lin.H * d.asDiagonal();
          const Eigen::MatrixXd inv = Hs.llt().solve(Eigen::MatrixXd::Identity(Hs.rows(), Hs.cols()));
          result.covariance = s2 * (d.asDiagonal() * inv * d.asDiagonal());
        }
      }
      return finish(Termination::kConverged, decision.message);
    }
    // Gauss-Newton step with backtracking: a step that raises the cost is halved.
    bool accepted = false;
    double alpha = 1.0;
    for (int h = 0; h <= kMaxHalvings && !accepted; ++h, alpha *= 0.5) {
      RobotModel candidate = model;
      ApplyUpdate(p, alpha * x, &candidate);
      Linearization next = Linearize(candidate, data, p, options, stack);
      if (next.finite && next.cost <= lin.cost * (1 + kCostIncreaseTolerance) + 1e-300) {
        model = std::move(candidate);
        previous_cost = lin.cost;
        lin = std::move(next);
        accepted = true;
      }
    }
    if (!accepted) {
      result.model = model;
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
  result.iterations = options.max_iterations;
  result.final_cost = lin.cost;
  std::ostringstream os;
  os << "not converged after " << options.max_iterations << " iterations (last |x| = "
     << result.history[result.history.size() - 2].step_norm << ", tolerance "
     << options.step_tolerance << ")";
  return finish(Termination::kMaxIterations, os.str());
}

}  // namespace lpoe
