#include "normal_equations.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <thread>
#include <vector>

#include <glog/logging.h>

#include "lpoe/kinematics.h"
#include "lpoe/pose_measurement.h"
#include "lpoe/position_measurement.h"

namespace lpoe {
namespace internal {
namespace {

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

// Per-thread scratch (allocated once per thread and call, never per row).
struct Scratch {
  Eigen::MatrixXd A;  // m * kBlockPoses x P stacked Jacobian rows
  Eigen::VectorXd Y;  // m * kBlockPoses residuals
  std::vector<FrameRt> frames;
  // Joint-space blocks only.
  Eigen::MatrixXd term_Y;     // n x P_b: one term's regressor
  Eigen::MatrixXd R;          // n x K: [Y_b(q) basis_b] of the row
  Eigen::MatrixXd R_t;        // its transpose, accumulated first
  std::vector<Eigen::MatrixXd> basis_t;  // basis_b^T per block (filled on first use)
  std::vector<bool> identity;  // basis_b is the identity, per block (filled on first use)
  Eigen::MatrixXd J_q;        // m x n
  Eigen::VectorXd q_eff;      // n
};

// The joint-space side of one row: s->R = [Y_b(q) basis_b].
void EvaluateJointRegressor(const Parameterization& p, const double* q, Scratch* s) {
  const int n = static_cast<int>(s->q_eff.size());
  int column = 0;
  s->R_t.resize(s->R.cols(), n);
  for (size_t b = 0; b < p.joint_blocks.size(); ++b) {
    const JointBlock& block = p.joint_blocks[b];
    s->term_Y.resize(n, block.term->num_parameters());
    block.term->Regressor(q, s->term_Y.data());
    // R_b = Y_b basis_b over the non-zero entries of Y_b only: a physical regressor is sparse (a
    // joint's offset depends on its own parameters), and a dense product per row would repack the
    // basis every time (most of the cost of a calibration with joint-space terms). Accumulated
    // transposed, on basis_b^T, so that the inner loop runs over contiguous memory. An identity
    // basis (every parameter identifiable, or the whole block analysed) copies Y_b: the same
    // numbers, since y * 1 + 0 = y.
    const int kb = static_cast<int>(block.basis.cols());
    if (s->basis_t.size() <= b) {
      s->basis_t.push_back(block.basis.transpose());
      s->identity.push_back(block.basis.rows() == kb && block.basis.isIdentity(0));
    }
    const Eigen::MatrixXd& Bt = s->basis_t[b];
    auto Rt = s->R_t.middleRows(column, kb);
    if (s->identity[b]) {
      Rt = s->term_Y.transpose();
    } else {
      Rt.setZero();
      for (int c = 0; c < s->term_Y.cols(); ++c) {
        for (int j = 0; j < n; ++j) {
          const double y = s->term_Y(j, c);
          if (y != 0) Rt.col(j) += y * Bt.col(c);
        }
      }
    }
    column += kb;
  }
  s->R = s->R_t.transpose();
}

// Accumulates rows [begin, end) into `sums` (and into the stacked J and y when `stacked`).
template <typename Kind>
void AccumulateRows(const Kind& kind, const BasisJacobian& bj, const Parameterization& p,
                    const Eigen::VectorXd& joint_state, const MeasurementSet& data, int begin,
                    int end, const Eigen::MatrixXd* joint_rows, Scratch* scratch,
                    ChunkSums* sums, NormalEquations* stacked) {
  constexpr int m = Kind::kResiduals;
  const int ld = m * kBlockPoses;
  const int K = p.num_joint_parameters();
  const int frame_columns = p.num_parameters - K;
  const int n = data.num_joints();
  const bool cached = joint_rows != nullptr && joint_rows->size() > 0;
  double* A = scratch->A.data();
  double* Y = scratch->Y.data();
  FrameRt* frames = scratch->frames.data();
  for (int r0 = begin; r0 < end; r0 += kBlockPoses) {
    const int count = std::min(kBlockPoses, end - r0);
    for (int k = 0; k < count; ++k) {
      const int r = r0 + k;
      double* Jr = A + m * k;
      double* y = Y + m * k;
      const typename Kind::Observation measured = Kind::Observe(data, r);
      double e;
      if (K == 0) {
        e = kind.Linearize(bj, data.q(r), data.target(r), measured, Jr, ld, nullptr, 0, frames, y);
      } else {
        const double* q = data.q(r);
        if (!cached) EvaluateJointRegressor(p, q, scratch);
        const Eigen::Map<const Eigen::MatrixXd> R(
            cached ? joint_rows->data() + static_cast<std::ptrdiff_t>(r) * n * K
                   : scratch->R.data(),
            n, K);
        scratch->q_eff = Eigen::Map<const Eigen::VectorXd>(q, n);
        if (joint_state.size() > 0) scratch->q_eff.noalias() += R * joint_state;
        e = kind.Linearize(bj, scratch->q_eff.data(), data.target(r), measured, Jr, ld,
                           scratch->J_q.data(), m, frames, y);
        // The joint blocks' columns, by the chain rule through q_eff.
        Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>> Jj(
            Jr + static_cast<std::ptrdiff_t>(frame_columns) * ld, m, K, Eigen::OuterStride<>(ld));
        Jj.noalias() = scratch->J_q.lazyProduct(R);  // small: no GEMM packing
      }
      double y_sq = 0;
      for (int i = 0; i < m; ++i) y_sq += y[i] * y[i];
      sums->cost += 0.5 * y_sq;
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

template <typename Kind>
NormalEquations Accumulate(const Kind& kind, const RobotModel& model, const MeasurementSet& data,
                           const Parameterization& p, const Eigen::VectorXd& joint_state,
                           bool stack, const Eigen::MatrixXd* joint_rows) {
  constexpr int m = Kind::kResiduals;
  const int P = p.num_parameters;
  const int N = data.size();
  const int n = model.num_joints();
  const int K = p.num_joint_parameters();
  CHECK(joint_state.size() == 0 || joint_state.size() == K);
  CHECK(joint_rows == nullptr || joint_rows->size() == 0 ||
        (joint_rows->rows() == n && joint_rows->cols() == static_cast<Eigen::Index>(K) * N));
  NormalEquations lin;
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
    s.frames.resize(n + 1);
    if (K > 0) {
      s.R.resize(n, K);
      s.J_q.resize(m, n);
      s.q_eff.resize(n);
    }
    return s;
  };
  auto run_chunk = [&](int c, Scratch* scratch) {
    ChunkSums& cs = sums[c];
    cs.H.setZero(P, P);
    cs.g.setZero(P);
    const int begin = std::min(N, c * chunk_size);
    const int end = std::min(N, begin + chunk_size);
    AccumulateRows(kind, bj, p, joint_state, data, begin, end, joint_rows, scratch, &cs,
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

}  // namespace

NormalEquations NormalEquationsOf(const RobotModel& model, const MeasurementSet& data,
                                  const Parameterization& p, const Eigen::VectorXd& joint_state,
                                  bool use_orientation, double orientation_weight, bool stack,
                                  const Eigen::MatrixXd* joint_rows) {
  if (use_orientation) {
    PoseMeasurement kind;
    kind.orientation_weight = orientation_weight;
    return Accumulate(kind, model, data, p, joint_state, stack, joint_rows);
  }
  return Accumulate(PositionMeasurement(), model, data, p, joint_state, stack, joint_rows);
}

Eigen::MatrixXd JointRegressorRows(const Parameterization& p, const MeasurementSet& data) {
  const int K = p.num_joint_parameters();
  const int n = data.num_joints();
  const double bytes = 8.0 * n * K * static_cast<double>(data.size());
  if (K == 0 || bytes > kMaxJointRowsBytes) return Eigen::MatrixXd();
  Eigen::MatrixXd rows(n, static_cast<Eigen::Index>(K) * data.size());
  Scratch s;
  s.R.resize(n, K);
  s.q_eff.resize(n);
  for (int r = 0; r < data.size(); ++r) {
    EvaluateJointRegressor(p, data.q(r), &s);
    rows.middleCols(static_cast<Eigen::Index>(r) * K, K) = s.R;
  }
  return rows;
}

}  // namespace internal
}  // namespace lpoe
