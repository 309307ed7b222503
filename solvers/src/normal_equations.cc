#include "normal_equations.h"

#include <algorithm>
#include <cstddef>
#include <cmath>
#include <vector>

#include <glog/logging.h>
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include "lpoe/kinematics.h"
#include "lpoe/parallel.h"
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
  // sin and cos of the joint values of a block of rows (SinCosMany; no joint-space blocks).
  std::vector<double> sin_q, cos_q;
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

// H (lower triangle; column-major, leading dimension P) += A^T A for A (rows x P, column-major,
// leading dimension ld): Eigen's blocked SYRK, or on processors with AVX2 and FMA (most x86-64 since
// 2013) a kernel of 2 x 4 tiles of H, each a set of dot products of A's contiguous columns in
// 4-wide fused multiply-adds, about twice as fast at P = 27. Either is deterministic; they differ
// in the last bits (another summation order), as builds with other flags would.
#if defined(__x86_64__) && defined(__GNUC__)
#define LPOE_HAVE_AVX2_KERNEL 1
__attribute__((target("avx2,fma"))) void SyrkLowerAvx2(const double* A, int ld, int rows, int P,
                                                       double* H) {
  constexpr int kTi = 2, kTj = 4;
  const int k4 = rows & ~3;
  for (int j0 = 0; j0 < P; j0 += kTj) {
    for (int i0 = j0; i0 < P; i0 += kTi) {
      // Columns past the last are read again from the last one and their results dropped.
      const double* a[kTi];
      const double* b[kTj];
      for (int t = 0; t < kTi; ++t) a[t] = A + static_cast<std::ptrdiff_t>(std::min(i0 + t, P - 1)) * ld;
      for (int t = 0; t < kTj; ++t) b[t] = A + static_cast<std::ptrdiff_t>(std::min(j0 + t, P - 1)) * ld;
      __m256d acc[kTi][kTj];
      for (auto& row : acc) {
        for (__m256d& v : row) v = _mm256_setzero_pd();
      }
      for (int k = 0; k < k4; k += 4) {
        __m256d bv[kTj];
        for (int t = 0; t < kTj; ++t) bv[t] = _mm256_loadu_pd(b[t] + k);
        for (int s = 0; s < kTi; ++s) {
          const __m256d av = _mm256_loadu_pd(a[s] + k);
          for (int t = 0; t < kTj; ++t) acc[s][t] = _mm256_fmadd_pd(av, bv[t], acc[s][t]);
        }
      }
      for (int s = 0; s < kTi; ++s) {
        for (int t = 0; t < kTj; ++t) {
          const int i = i0 + s, j = j0 + t;
          if (i >= P || j >= P || i < j) continue;
          alignas(32) double lanes[4];
          _mm256_store_pd(lanes, acc[s][t]);
          double sum = (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]);
          for (int k = k4; k < rows; ++k) sum += a[s][k] * b[t][k];
          H[static_cast<std::ptrdiff_t>(j) * P + i] += sum;
        }
      }
    }
  }
}

bool HaveAvx2() {
  static const bool have = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return have;
}
#endif

void SyrkLower(const Eigen::MatrixXd& A, int rows, Eigen::MatrixXd* H) {
#ifdef LPOE_HAVE_AVX2_KERNEL
  if (HaveAvx2()) {
    SyrkLowerAvx2(A.data(), static_cast<int>(A.rows()), rows, static_cast<int>(A.cols()),
                  H->data());
    return;
  }
#endif
  H->selfadjointView<Eigen::Lower>().rankUpdate(A.topRows(rows).transpose());
}

// Accumulates rows [begin, end) into `sums` (and into the stacked J and y when `stacked`).
template <typename Kind>
void AccumulateRows(const Kind& kind, const BasisJacobian& bj, const Parameterization& p,
                    const Eigen::VectorXd& joint_state, const MeasurementSet& data, int begin,
                    int end, const Eigen::MatrixXd* joint_rows, Scratch* scratch,
                    ChunkSums* sums, NormalEquations* stacked, int chunk,
                    PositionErrorRows* errors) {
  constexpr int m = Kind::kResiduals;
  const int ld = m * kBlockPoses;
  const int K = p.num_joint_parameters();
  const int frame_columns = p.num_parameters - K;
  const int n = data.num_joints();
  const bool cached = joint_rows != nullptr && joint_rows->size() > 0;
  double* A = scratch->A.data();
  double* Y = scratch->Y.data();
  FrameRt* frames = scratch->frames.data();
  // Without joint-space blocks the rows' joint values are the measured ones: sin and cos of a whole
  // block at once.
  const bool block_sincos = K == 0 && n <= kMaxGivenSinCosJoints;
  for (int r0 = begin; r0 < end; r0 += kBlockPoses) {
    const int count = std::min(kBlockPoses, end - r0);
    if (block_sincos) {
      SinCosMany(data.q(r0), count * n, scratch->sin_q.data(), scratch->cos_q.data());
    }
    for (int k = 0; k < count; ++k) {
      const int r = r0 + k;
      double* Jr = A + m * k;
      double* y = Y + m * k;
      const typename Kind::Observation measured = Kind::Observe(data, r);
      double e;
      if (K == 0) {
        const double* s = block_sincos ? scratch->sin_q.data() + k * n : nullptr;
        const double* c = block_sincos ? scratch->cos_q.data() + k * n : nullptr;
        e = kind.Linearize(bj, data.q(r), data.target(r), measured, Jr, ld, nullptr, 0, frames, y,
                           s, c);
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
      if constexpr (m == 3) {
        if (errors != nullptr) errors->Record(chunk, r, Eigen::Vector3d(y[0], y[1], y[2]));
      }
      double y_sq = 0;
      for (int i = 0; i < m; ++i) y_sq += y[i] * y[i];
      sums->cost += 0.5 * y_sq;
      sums->max_error = std::max(sums->max_error, e);
      sums->sum_error += e;
    }
    const int rows = m * count;
    const auto Ab = scratch->A.topRows(rows);
    SyrkLower(scratch->A, rows, &sums->H);
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
                           bool stack, const Eigen::MatrixXd* joint_rows,
                           PositionErrorRows* errors) {
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

  const RowChunks chunks = PartitionRows(N, kMinChunkPoses, kMaxChunks);
  std::vector<ChunkSums> sums(chunks.chunks);
  if (m != 3 || K > 0) errors = nullptr;
  if (errors != nullptr) errors->Reset(N, chunks.chunks);
  const int threads = N < kMinPosesForThreads ? 1 : ThreadsFor(chunks.chunks);
  std::vector<Scratch> scratch(threads);
  for (Scratch& s : scratch) {
    s.A.resize(static_cast<Eigen::Index>(m) * kBlockPoses, P);
    s.Y.resize(static_cast<Eigen::Index>(m) * kBlockPoses);
    s.frames.resize(n + 1);
    if (K == 0) {
      s.sin_q.resize(static_cast<size_t>(n) * kBlockPoses);
      s.cos_q.resize(static_cast<size_t>(n) * kBlockPoses);
    }
    if (K > 0) {
      s.R.resize(n, K);
      s.J_q.resize(m, n);
      s.q_eff.resize(n);
    }
  }
  // Chunks are taken in any order; each writes only its own sums (and its own rows of J, y).
  ForEachTask(chunks.chunks, threads, [&](int c, int thread) {
    ChunkSums& cs = sums[c];
    cs.H.setZero(P, P);
    cs.g.setZero(P);
    AccumulateRows(kind, bj, p, joint_state, data, chunks.begin(c), chunks.end(c), joint_rows,
                   &scratch[thread], &cs, stack ? &lin : nullptr, c, errors);
  });
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
                                  const Eigen::MatrixXd* joint_rows, PositionErrorRows* errors) {
  if (use_orientation) {
    PoseMeasurement kind;
    kind.orientation_weight = orientation_weight;
    return Accumulate(kind, model, data, p, joint_state, stack, joint_rows, errors);
  }
  return Accumulate(PositionMeasurement(), model, data, p, joint_state, stack, joint_rows, errors);
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
