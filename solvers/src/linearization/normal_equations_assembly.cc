// The linearized problem accumulated as normal equations (normal_equations.h: NormalEquationsOf,
// JointRegressorRows): rows one at a time (BasisJacobian), or four at a time through the kernels of
// core/src/kernels/ (lpoe/kinematics/kernels.h), and the joint-space blocks by their structure. The regressors
// in slot form and the projections of joint blocks are in normal_equations_regressors.cc, a row's
// joint-term columns in joint_term_columns.cc (shared with the Ceres problem).
#include "linearization/normal_equations.h"

#include <algorithm>
#include <cstddef>
#include <cmath>
#include <vector>

#include <glog/logging.h>

#include "calibration/block_kind.h"
#include "linearization/joint_term_columns.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kernels.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "lpoe/parallel.h"
#include "lpoe/measurements/pose_measurement.h"
#include "lpoe/measurements/position_measurement.h"

namespace lpoe {
namespace internal {
namespace {

using kernels::FourRowPlan;

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

// Every entry finite: what Eigen's allFinite() tells, in one plain pass (allFinite evaluates x - x
// == x - x entry by entry, about five times the instructions on a 79 x 79 normal matrix).
template <typename Matrix>
bool AllFinite(const Matrix& m) {
  const double* x = m.data();
  const Eigen::Index size = m.size();
  bool finite = true;
  for (Eigen::Index i = 0; i < size; ++i) finite &= std::isfinite(x[i]);
  return finite;
}

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
  JointTermColumns columns;   // the rows' joint-term columns (joint_term_columns.h)
  Eigen::MatrixXd R;          // n x K: [Y_b(q) basis_b] of the row
  Eigen::MatrixXd J_q;        // m x n
  Eigen::VectorXd q_eff;      // n
  Eigen::MatrixXd R_bilinear;  // R with the block kinds' columns (block_kind.h)
};

// H (lower triangle) += A^T A for the first `rows` rows and `cols` columns of A (J^T J written once:
// the AVX2 kernel or Eigen's rank update, lpoe/kinematics/kernels.h).
void SyrkLower(const Eigen::MatrixXd& A, int rows, int cols, Eigen::MatrixXd* H) {
  if (kernels::Avx2Fma()) {
    kernels::SyrkLowerAvx2(A.data(), static_cast<int>(A.rows()), rows, cols, H->data(),
                           static_cast<int>(H->rows()));
    return;
  }
  H->selfadjointView<Eigen::Lower>().rankUpdate(A.topLeftCorner(rows, cols).transpose());
}

// ---- Position rows four at a time.
//
// The common case at scale (position data, no joint-space blocks, every joint revolute about z,
// every basis column a canonical direction: the identifiable parameterization of such a chain)
// evaluates four rows at once, one per AVX2 lane: the forward pass on the frames
// G_i = T_0,i-1(q) T_{i-1,i}(0) (BasisJacobian::Position, eq. (29)) and the canonical columns of
// each frame's block. A block's rows are stored component-major (row i * stride + k: component i of
// pose k, so that four poses' values are one store) with y as the extra column P, so that one SYRK
// gives J^T J and J^T y together. The sums are those of AccumulateRows up to round-off (another
// order of the same products).

FourRowPlan MakeFourRowPlan(const RobotModel& model, const Parameterization& p,
                            bool joint_blocks = false) {
  FourRowPlan plan;
  if (!kernels::Avx2Fma() || model.num_joints() > kMaxGivenSinCosJoints ||
      (p.num_joint_parameters() > 0 && !joint_blocks)) {
    return plan;
  }
  for (const Joint& j : model.joints) {
    if (!IsRevoluteZ(j)) return plan;
  }
  for (int f = 0; f < model.num_frames(); ++f) {
    FourRowPlan::Frame fr;
    fr.offset = p.offset[f];
    const Eigen::MatrixXd& B = p.basis[f];
    for (int c = 0; c < B.cols(); ++c) {
      int one = -1;
      for (int r = 0; r < 6; ++r) {
        if (B(r, c) == 1.0 && one < 0) {
          one = r;
        } else if (B(r, c) != 0.0) {
          return plan;
        }
      }
      if (one < 0) return plan;
      fr.select.push_back(one);
    }
    plan.frames.push_back(std::move(fr));
  }
  plan.ok = true;
  return plan;
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
  const bool nonlinear = K > 0 && HasNonlinearBlocks(p);
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
        if (!cached) scratch->columns.Evaluate(r, q, &scratch->R);
        const Eigen::Map<const Eigen::MatrixXd> R(
            cached ? joint_rows->data() + static_cast<std::ptrdiff_t>(r) * n * K
                   : scratch->R.data(),
            n, K);
        scratch->q_eff = Eigen::Map<const Eigen::VectorXd>(q, n);
        if (joint_state.size() > 0) scratch->q_eff.noalias() += R * joint_state;
        if (nonlinear) {  // the block kinds' columns at the current values (block_kind.h)
          scratch->R_bilinear = R;
          AddNonlinearRowColumns(p, q, joint_state, scratch->R_bilinear, &scratch->q_eff);
        }
        const Eigen::Ref<const Eigen::MatrixXd> Rj =
            nonlinear ? Eigen::Ref<const Eigen::MatrixXd>(scratch->R_bilinear)
                      : Eigen::Ref<const Eigen::MatrixXd>(R);
        e = kind.Linearize(bj, scratch->q_eff.data(), data.target(r), measured, Jr, ld,
                           scratch->J_q.data(), m, frames, y);
        // The joint blocks' columns, by the chain rule through q_eff.
        Eigen::Map<Eigen::MatrixXd, 0, Eigen::OuterStride<>> Jj(
            Jr + static_cast<std::ptrdiff_t>(frame_columns) * ld, m, K, Eigen::OuterStride<>(ld));
        Jj.noalias() = scratch->J_q.lazyProduct(Rj);  // small: no GEMM packing
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
    SyrkLower(scratch->A, rows, static_cast<int>(scratch->A.cols()), &sums->H);
    sums->g.noalias() += Ab.transpose() * scratch->Y.head(rows);
    if (stacked != nullptr) {
      stacked->J.middleRows(static_cast<Eigen::Index>(m) * r0, rows) = Ab;
      stacked->y.segment(static_cast<Eigen::Index>(m) * r0, rows) = scratch->Y.head(rows);
    }
  }
}

// Rows [begin, end) four at a time (PositionRows4) into `sums`, whose H is (P + 1) square: J^T J,
// then J^T y in row P.
void AccumulatePositionRows4(const RobotModel& model, const FourRowPlan& plan,
                             const MeasurementSet& data, int begin, int end, Scratch* scratch,
                             ChunkSums* sums, int chunk, PositionErrorRows* errors) {
  const int n = model.num_joints();
  const int P1 = static_cast<int>(scratch->A.cols());  // P + 1
  const int ld = static_cast<int>(scratch->A.rows());
  double* A = scratch->A.data();
  double* Y = A + static_cast<std::ptrdiff_t>(P1 - 1) * ld;
  for (int r0 = begin; r0 < end; r0 += kBlockPoses) {
    const int count = std::min(kBlockPoses, end - r0);
    const int stride = (count + 3) & ~3;
    SinCosMany(data.q(r0), count * n, scratch->sin_q.data(), scratch->cos_q.data());
    for (int g = 0; g < count; g += 4) {
      const int valid = std::min(4, count - g);
      int tool[4];
      for (int l = 0; l < 4; ++l) tool[l] = l < valid ? data.target(r0 + g + l) : 0;
      double Pm[12];
      kernels::PositionRows4(model, plan, scratch->sin_q.data() + static_cast<std::ptrdiff_t>(g) * n,
                    scratch->cos_q.data() + static_cast<std::ptrdiff_t>(g) * n, tool, valid,
                    A + g, ld, stride, Pm);
      for (int l = 0; l < 4; ++l) {
        for (int i = 0; i < 3; ++i) {
          Y[i * stride + g + l] = l < valid ? data.position(r0 + g + l)(i) - Pm[4 * i + l] : 0.0;
        }
      }
    }
    for (int k = 0; k < count; ++k) {
      const Eigen::Vector3d y(Y[k], Y[stride + k], Y[2 * stride + k]);
      if (errors != nullptr) errors->Record(chunk, r0 + k, y);
      const double y_sq = y.squaredNorm();
      const double e = y.norm();
      sums->cost += 0.5 * y_sq;
      sums->max_error = std::max(sums->max_error, e);
      sums->sum_error += e;
    }
    SyrkLower(scratch->A, 3 * stride, P1, &sums->H);
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

  const FourRowPlan plan =
      m == 3 && K == 0 && !stack ? MakeFourRowPlan(model, p) : FourRowPlan();
  const bool four = plan.ok;
  lin.four_rows = four;
  const RowChunks chunks = PartitionRows(N, kMinChunkPoses, kMaxChunks);
  std::vector<ChunkSums> sums(chunks.chunks);
  if (m != 3 || K > 0) errors = nullptr;
  if (errors != nullptr) errors->Reset(N, chunks.chunks);
  const int threads = N < kMinPosesForThreads ? 1 : ThreadsFor(chunks.chunks);
  std::vector<Scratch> scratch(threads);
  for (Scratch& s : scratch) {
    // The four-row path keeps y as column P of A (and reads up to three lanes past a block).
    s.A.setZero(static_cast<Eigen::Index>(m) * kBlockPoses, four ? P + 1 : P);
    s.Y.resize(static_cast<Eigen::Index>(m) * kBlockPoses);
    s.frames.resize(n + 1);
    if (K == 0) {
      s.sin_q.resize(static_cast<size_t>(n) * (kBlockPoses + 4));
      s.cos_q.resize(static_cast<size_t>(n) * (kBlockPoses + 4));
    }
    if (K > 0) {
      // The block kinds' columns (past the joint blocks') are zero here, set by
      // AddNonlinearRowColumns.
      s.columns = JointTermColumns(p, n, K);
      s.R.resize(n, K);
      s.J_q.resize(m, n);
      s.q_eff.resize(n);
    }
  }
  // Chunks are taken in any order; each writes only its own sums (and its own rows of J, y).
  ForEachTask(chunks.chunks, threads, [&](int c, int thread) {
    ChunkSums& cs = sums[c];
    cs.H.setZero(four ? P + 1 : P, four ? P + 1 : P);
    cs.g.setZero(P);
    if (four) {
      AccumulatePositionRows4(model, plan, data, chunks.begin(c), chunks.end(c), &scratch[thread],
                              &cs, c, errors);
      return;
    }
    AccumulateRows(kind, bj, p, joint_state, data, chunks.begin(c), chunks.end(c), joint_rows,
                   &scratch[thread], &cs, stack ? &lin : nullptr, c, errors);
  });
  // Fixed-order reduction.
  double sum_error = 0;
  for (const ChunkSums& cs : sums) {
    if (four) {
      lin.H += cs.H.topLeftCorner(P, P);
      lin.g += cs.H.row(P).head(P).transpose();
    } else {
      lin.H += cs.H;
      lin.g += cs.g;
    }
    lin.cost += cs.cost;
    lin.max_error = std::max(lin.max_error, cs.max_error);
    sum_error += cs.sum_error;
  }
  lin.H.triangularView<Eigen::StrictlyUpper>() = lin.H.transpose();
  lin.mean_error = data.empty() ? 0.0 : sum_error / data.size();
  lin.finite = std::isfinite(lin.cost) && AllFinite(lin.H) && AllFinite(lin.g);
  return lin;
}


// ---- Joint-space blocks by their structure (normal_equations.h, JointSpaceRegressors).

// Per-chunk sums of the structured path: the frames' block as in the dense path, the frames x slots
// block, W with W + W^T the slots' block, and the slots' gradient.
struct SlotSums {
  Eigen::MatrixXd H;    // lower triangle; F x F, or (F + S) x (F + S) with the joint blocks (the
                        // frames' and the slots' columns: H_ff, H_sf and W)
  Eigen::VectorXd g;    // F
  Eigen::VectorXd gs;   // S
  // Four-row path (AccumulateSlots4): the frames' block and gradient as one (F + 1) square lower
  // triangle (J^T J, then J^T y in row F); H then holds the slots' rows only.
  Eigen::MatrixXd Hfy;
  double cost = 0;
  double max_error = 0;
  double sum_error = 0;
};

struct SlotScratch {
  Eigen::MatrixXd A;   // m * kBlockPoses x max(P, F + S): frame rows in the first F columns (the
                       // measurement kinds may touch all P, see PoseMeasurement::Linearize), then
                       // with the joint blocks the rows in slot coordinates (S columns)
  Eigen::VectorXd Y;   // m * kBlockPoses residuals
  std::vector<FrameRt> frames;
  Eigen::MatrixXd J_q;     // m x n
  Eigen::VectorXd q_eff;   // n
  Eigen::VectorXd h;       // n: J_q^T y
  Eigen::MatrixXd V;       // S x kBlockPoses: slot values (when not stored)
  Eigen::MatrixXd term_Y;  // one block's regressor
};

// Row r's slot values into v (the regressors evaluated at q).
void EvaluateSlots(const Parameterization& p, const JointSpaceRegressors& regs, const double* q,
                   Eigen::MatrixXd* term_Y, double* v) {
  const int n = regs.num_joints;
  int s = 0;
  for (int j = 0; j < n; ++j) {
    for (; s < regs.slot_begin[j + 1]; ++s) v[s] = 0;
  }
  for (size_t b = 0; b < p.joint_blocks.size(); ++b) {
    const JointTerm& term = *p.joint_blocks[b].term;
    const int first = regs.column_offset[b], last = regs.column_offset[b + 1];
    // The entries at each parameter's joint alone when the term gives them (RegressorValues).
    const bool single_joint = b < regs.one_joint_each.size() && regs.one_joint_each[b];
    term_Y->resize(term.num_parameters(), 1);
    if (single_joint && term.RegressorValues(q, term_Y->data())) {
      for (int t = 0; t < regs.num_slots(); ++t) {
        const int c = regs.slot_column[t];
        if (c >= first && c < last) v[t] = (*term_Y)(c - first);
      }
      continue;
    }
    term_Y->resize(n, term.num_parameters());
    term.Regressor(q, term_Y->data());
    for (int j = 0; j < n; ++j) {
      for (int t = regs.slot_begin[j]; t < regs.slot_begin[j + 1]; ++t) {
        const int c = regs.slot_column[t];
        if (c >= first && c < last) v[t] = (*term_Y)(j, c - first);
      }
    }
  }
}

template <typename Kind>
void AccumulateSlots(const Kind& kind, const BasisJacobian& bj, const Parameterization& p,
                     const Eigen::VectorXd& theta_slots, const JointSpaceRegressors& regs,
                     bool blocks, const MeasurementSet& data, int begin, int end, SlotScratch* s,
                     SlotSums* sums) {
  constexpr int m = Kind::kResiduals;
  const int ld = m * kBlockPoses;
  const int F = p.num_frame_parameters();
  const int n = data.num_joints();
  const int S = regs.num_slots();
  const bool stored = regs.values.size() > 0;
  const bool moved = theta_slots.size() > 0;
  double* A = s->A.data();
  double* Y = s->Y.data();
  FrameRt* frames = s->frames.data();
  for (int r0 = begin; r0 < end; r0 += kBlockPoses) {
    const int count = std::min(kBlockPoses, end - r0);
    for (int k = 0; k < count; ++k) {
      const int r = r0 + k;
      const double* q = data.q(r);
      // Stored values are read; otherwise evaluated into the scratch V (sized only then).
      const double* v;
      if (stored) {
        v = regs.values.col(r).data();
      } else {
        double* vk = s->V.col(k).data();
        EvaluateSlots(p, regs, q, &s->term_Y, vk);
        v = vk;
      }
      for (int j = 0; j < n; ++j) {
        double dq = 0;
        if (moved) {
          for (int t = regs.slot_begin[j]; t < regs.slot_begin[j + 1]; ++t) {
            dq += v[t] * theta_slots(t);
          }
        }
        s->q_eff(j) = q[j] + dq;
      }
      double* Jr = A + m * k;
      double* y = Y + m * k;
      const double e = kind.Linearize(bj, s->q_eff.data(), data.target(r), Kind::Observe(data, r),
                                      Jr, ld, s->J_q.data(), m, frames, y);
      const Eigen::Map<const Eigen::Matrix<double, m, 1>> yv(y);
      s->h.noalias() = s->J_q.transpose() * yv;
      for (int j = 0; j < n; ++j) {
        const double hj = s->h(j);
        for (int t = regs.slot_begin[j]; t < regs.slot_begin[j + 1]; ++t) sums->gs(t) += v[t] * hj;
      }
      if (blocks) {
        // The pose's rows in slot coordinates, after its frame columns: column F + t holds
        // J_q col j * v[t] for slot t of joint j (the dense rows' column of slot_column[t]).
        for (int j = 0; j < n; ++j) {
          const double* jq = s->J_q.col(j).data();
          for (int t = regs.slot_begin[j]; t < regs.slot_begin[j + 1]; ++t) {
            double* u = A + static_cast<std::ptrdiff_t>(F + t) * ld + m * k;
            const double vt = v[t];
            for (int c = 0; c < m; ++c) u[c] = jq[c] * vt;
          }
        }
      }
      double y_sq = 0;
      for (int i = 0; i < m; ++i) y_sq += y[i] * y[i];
      sums->cost += 0.5 * y_sq;
      sums->max_error = std::max(sums->max_error, e);
      sums->sum_error += e;
    }
    const int rows = m * count;
    // With the joint blocks one product gives H_ff, H_sf and W = sum of the slot columns' outer
    // products (the frames' kernel on F + S columns): W's pairs of joints j, i are
    // V_j diag((J_q^T J_q)_ji) V_i^T over the poses, formed here from the factor J_q instead.
    SyrkLower(s->A, rows, blocks ? F + S : F, &sums->H);
    sums->g.noalias() += s->A.topLeftCorner(rows, F).transpose() * s->Y.head(rows);
  }
}

// ---- Position rows four at a time with joint-space blocks.
//
// Where the four-row path applies (position data, revolute-z joints, canonical frame columns) the
// rows are evaluated four poses at a time as in the geometric pass, with the joint Jacobian J_q as
// n more columns, and the slots' blocks are not formed from slot columns per row but per group of
// up to kSlotGroupPoses poses as a few matrix products over the poses, from three small per-pose
// products: h_p = J_q^T y, G_p = J_q^T J_q (lower triangle) and C_p = A_p^T J_q (A_p: the pose's
// frame rows). For slot t of joint j and slot u of joint i (v: the slots' values, V_j: joint j's
// slot rows over the poses):
//   gs_t = sum_p v_t(p) h_p(j)                  gs_j    = V_j h(j)
//   (H_slots,frames)_t = sum_p v_t(p) C_p(:, j)  H_sj,f  = V_j C_j
//   W_tu = sum_p v_t(p) v_u(p) G_p(j, i)          W_ji    = V_j diag(G(j, i)) V_i^T
// the same sums as the slot columns' (J_q col j * v_t) products in another order:
// (3 n + 3 n (n + 1) / 2 + 3 n F) multiply-adds per pose plus (F S + S (S + 1) / 2 + ...) in the
// products, against 3 (F + S) (F + S + 1) / 2 for the rank-k update of the slot columns.
constexpr int kSlotGroupPoses = 1024;

struct SlotScratch4 {
  Eigen::MatrixXd A;  // 3 kBlockPoses x (F + 1 + n): frame columns, y, J_q (PositionRows4 layout)
  std::vector<double> q_eff, sin_q, cos_q;  // n values per pose of a block
  int group = 0;      // rows of h, G, C (kSlotGroupPoses, or fewer for small data)
  Eigen::MatrixXd V;  // S x group: slot values when not stored
  Eigen::MatrixXd dq;  // n x group: q_eff - q
  Eigen::MatrixXd h;   // group x n
  Eigen::MatrixXd G;   // group x n (n + 1) / 2: column j (j + 1) / 2 + i, i <= j
  Eigen::MatrixXd C;   // group x n F: column j F + f
  Eigen::MatrixXd VT;  // group x S: the slots' values transposed (columns over the poses)
  Eigen::MatrixXd term_Y;
};

// Rows [begin, end) four at a time into `sums` (Hfy, gs and with `blocks` the slots' rows of H).
void AccumulateSlots4(const RobotModel& model, const FourRowPlan& plan, const Parameterization& p,
                      const Eigen::VectorXd& theta_slots, const JointSpaceRegressors& regs,
                      bool blocks, const MeasurementSet& data, int begin, int end,
                      SlotScratch4* s, SlotSums* sums) {
  const int n = model.num_joints();
  const int F = p.num_frame_parameters();
  const int S = regs.num_slots();
  const int ld = static_cast<int>(s->A.rows());
  double* A = s->A.data();
  double* Y = A + static_cast<std::ptrdiff_t>(F) * ld;
  const bool stored = regs.values.size() > 0;
  const bool moved = theta_slots.size() > 0;
  const int ldo = s->group;
  for (int s0 = begin; s0 < end; s0 += ldo) {
    const int ns = std::min(ldo, end - s0);
    if (!stored) {
      for (int k = 0; k < ns; ++k) {
        EvaluateSlots(p, regs, data.q(s0 + k), &s->term_Y, s->V.col(k).data());
      }
    }
    const Eigen::Map<const Eigen::MatrixXd> V(
        stored ? regs.values.data() + static_cast<std::ptrdiff_t>(s0) * S : s->V.data(), S, ns);
    if (moved) {
      for (int j = 0; j < n; ++j) {
        const int b = regs.slot_begin[j], c = regs.slot_begin[j + 1] - b;
        if (c == 0) {
          s->dq.row(j).head(ns).setZero();
        } else {
          s->dq.row(j).head(ns).noalias() =
              theta_slots.segment(b, c).transpose() * V.middleRows(b, c);
        }
      }
    }
    for (int r0 = s0; r0 < s0 + ns; r0 += kBlockPoses) {
      const int count = std::min(kBlockPoses, s0 + ns - r0);
      const int stride = (count + 3) & ~3;
      const int k0 = r0 - s0;
      const double* q = data.q(r0);
      double* qe = s->q_eff.data();
      for (int k = 0; k < count; ++k) {
        for (int j = 0; j < n; ++j) {
          qe[k * n + j] = moved ? q[k * n + j] + s->dq(j, k0 + k) : q[k * n + j];
        }
      }
      SinCosMany(qe, count * n, s->sin_q.data(), s->cos_q.data());
      for (int g = 0; g < count; g += 4) {
        const int valid = std::min(4, count - g);
        int tool[4];
        for (int l = 0; l < 4; ++l) tool[l] = l < valid ? data.target(r0 + g + l) : 0;
        double Pm[12];
        kernels::PositionRows4(model, plan, s->sin_q.data() + static_cast<std::ptrdiff_t>(g) * n,
                      s->cos_q.data() + static_cast<std::ptrdiff_t>(g) * n, tool, valid, A + g, ld,
                      stride, Pm, F + 1);
        for (int l = 0; l < 4; ++l) {
          for (int i = 0; i < 3; ++i) {
            Y[i * stride + g + l] = l < valid ? data.position(r0 + g + l)(i) - Pm[4 * i + l] : 0.0;
          }
        }
      }
      for (int k = 0; k < count; ++k) {
        const Eigen::Vector3d y(Y[k], Y[stride + k], Y[2 * stride + k]);
        const double e = y.norm();
        sums->cost += 0.5 * y.squaredNorm();
        sums->max_error = std::max(sums->max_error, e);
        sums->sum_error += e;
      }
      SyrkLower(s->A, 3 * stride, F + 1, &sums->Hfy);
      kernels::PoseProducts4(A, ld, stride, F, n, blocks, s->h.data(), s->G.data(), s->C.data(), ldo, k0);
    }
    // The group's products over its poses: dot products of contiguous columns over the poses
    // (the slots' values transposed once per group).
    if (blocks) s->VT.topRows(ns) = V.transpose();
    for (int j = 0; j < n; ++j) {
      const int b = regs.slot_begin[j], c = regs.slot_begin[j + 1] - b;
      if (c == 0) continue;
      sums->gs.segment(b, c).noalias() += V.middleRows(b, c) * s->h.col(j).head(ns);
      if (!blocks) continue;
      const auto Vj = s->VT.block(0, b, ns, c);
      if (kernels::Avx2Fma()) {
        const int ldh = static_cast<int>(sums->H.rows());
        double* Hj = sums->H.data() + F + b;  // row F + b
        kernels::DotProductsAvx2(Vj.data(), ldo, c,
                                 s->C.data() + static_cast<std::ptrdiff_t>(j) * F * ldo, ldo, F,
                                 nullptr, ns, false, Hj, ldh);
        for (int i = 0; i <= j; ++i) {
          const int bi = regs.slot_begin[i], ci = regs.slot_begin[i + 1] - bi;
          if (ci == 0) continue;
          kernels::DotProductsAvx2(
              Vj.data(), ldo, c, s->VT.data() + static_cast<std::ptrdiff_t>(bi) * ldo, ldo, ci,
              s->G.data() + static_cast<std::ptrdiff_t>(j * (j + 1) / 2 + i) * ldo, ns, i == j,
              Hj + static_cast<std::ptrdiff_t>(F + bi) * ldh, ldh);
        }
        continue;
      }
      sums->H.block(F + b, 0, c, F).noalias() +=
          Vj.transpose() * s->C.block(0, static_cast<Eigen::Index>(j) * F, ns, F);
      for (int i = 0; i <= j; ++i) {
        const int bi = regs.slot_begin[i], ci = regs.slot_begin[i + 1] - bi;
        if (ci == 0) continue;
        const auto g = s->G.col(j * (j + 1) / 2 + i).head(ns);
        const Eigen::MatrixXd W = Vj.transpose() * g.asDiagonal() * s->VT.block(0, bi, ns, ci);
        if (i == j) {
          sums->H.block(F + b, F + bi, c, ci).triangularView<Eigen::Lower>() += W;
        } else {
          sums->H.block(F + b, F + bi, c, ci) += W;
        }
      }
    }
  }
}

// Whether T only selects columns: every row zero but for at most one entry equal to 1. `column`:
// that entry's column per row, -1 for a zero row (left empty when T does more than select).
bool SlotSelection(const Eigen::MatrixXd& T, std::vector<int>* column) {
  column->assign(T.rows(), -1);
  for (Eigen::Index c = 0; c < T.cols(); ++c) {
    for (Eigen::Index r = 0; r < T.rows(); ++r) {
      const double x = T(r, c);
      if (x == 0) continue;
      if (x != 1 || (*column)[r] >= 0) {
        column->clear();
        return false;
      }
      (*column)[r] = static_cast<int>(c);
    }
  }
  return true;
}

// The slots' sums mapped to p's joint coordinates: Hall (frames and slots, symmetric) and gs (the
// slots' gradient) into lin's joint rows and columns (H's frames block and g's frames part are
// lin's already). `blocks` false: the gradient only.
void MapSlotSumsToJointBlocks(const Eigen::MatrixXd& Hall, const Eigen::VectorXd& gs,
                              const JointSpaceRegressors& regs, const Parameterization& p,
                              bool blocks, NormalEquations* out) {
  NormalEquations& lin = *out;
  const int K = p.num_joint_parameters();
  const int F = p.num_parameters - K;
  const int S = regs.num_slots();
  const Eigen::MatrixXd& T = regs.slot_basis;
  std::vector<int> selected;
  const bool select = SlotSelection(T, &selected);
  if (select) {
    // Every block with the identity basis (the reduction's analysis): T only picks each slot's
    // column, so the products below are sums of the slots' entries (the same numbers exactly).
    for (int t = 0; t < S; ++t) {
      const int k = selected[t];
      if (k < 0) continue;
      lin.g(F + k) += gs(t);
      if (!blocks) continue;
      lin.H.col(F + k).head(F) += Hall.col(F + t).head(F);
      for (int u = 0; u < S; ++u) {
        if (selected[u] >= 0) lin.H(F + selected[u], F + k) += Hall(F + u, F + t);
      }
    }
    if (blocks) {
      lin.H.bottomLeftCorner(K, F) = lin.H.topRightCorner(F, K).transpose();
      // Exactly symmetric (a column picked by several slots sums them in another order).
      Eigen::MatrixXd Hkk = lin.H.bottomRightCorner(K, K);
      lin.H.bottomRightCorner(K, K) = 0.5 * (Hkk + Hkk.transpose());
    }
  } else {
    lin.g.tail(K).noalias() = T.transpose() * gs;
  }
  if (blocks && !select) {
    // H_frames,K = H_frames,slots T, W T and T^T (W T) block by block: slot t's row of T has only
    // its joint block's columns (SetSlotBasis), so per block b the rows of its slots and its
    // columns form a dense T_b and every other entry is zero. The products run over those rows
    // and columns only, the zero terms left out (half the multiply-adds with two blocks).
    struct SlotPart {
      int col = 0, cols = 0;
      std::vector<int> rows;
      Eigen::MatrixXd T;
    };
    std::vector<SlotPart> parts(p.joint_blocks.size());
    for (size_t b = 0; b < parts.size(); ++b) {
      parts[b].col = p.joint_blocks[b].offset - F;
      parts[b].cols = static_cast<int>(p.joint_blocks[b].basis.cols());
    }
    for (int t = 0; t < S; ++t) {
      size_t b = 0;
      while (regs.slot_column[t] >= regs.column_offset[b + 1]) ++b;
      parts[b].rows.push_back(t);
    }
    lin.H.topRightCorner(F, K).setZero();
    Eigen::MatrixXd WT = Eigen::MatrixXd::Zero(S, K);
    for (SlotPart& part : parts) {
      const int nb = static_cast<int>(part.rows.size());
      part.T.resize(nb, part.cols);
      Eigen::MatrixXd Hf(F, nb), Wb(S, nb);
      for (int i = 0; i < nb; ++i) {
        const int t = part.rows[i];
        part.T.row(i) = T.row(t).segment(part.col, part.cols);
        Hf.col(i) = Hall.col(F + t).head(F);
        Wb.col(i) = Hall.col(F + t).tail(S);
      }
      lin.H.block(0, F + part.col, F, part.cols).noalias() = Hf * part.T;
      WT.middleCols(part.col, part.cols).noalias() = Wb * part.T;
    }
    lin.H.bottomLeftCorner(K, F) = lin.H.topRightCorner(F, K).transpose();
    lin.H.bottomRightCorner(K, K).setZero();
    for (const SlotPart& part : parts) {
      const int nb = static_cast<int>(part.rows.size());
      Eigen::MatrixXd WTb(nb, K);
      for (int i = 0; i < nb; ++i) WTb.row(i) = WT.row(part.rows[i]);
      lin.H.block(F + part.col, F, part.cols, K).noalias() = part.T.transpose() * WTb;
    }
    // Exactly symmetric (the product's two triangles round differently).
    Eigen::MatrixXd Hkk = lin.H.bottomRightCorner(K, K);
    lin.H.bottomRightCorner(K, K) = 0.5 * (Hkk + Hkk.transpose());
  }
}

template <typename Kind>
NormalEquations AccumulateStructured(const Kind& kind, const RobotModel& model,
                                     const MeasurementSet& data, const Parameterization& p,
                                     const Eigen::VectorXd& joint_state,
                                     const JointSpaceRegressors& regs, bool gradient_only,
                                     bool four_rows) {
  constexpr int m = Kind::kResiduals;
  const int P = p.num_parameters;
  const int K = p.num_joint_parameters();
  const int F = P - K;
  const int N = data.size();
  const int n = model.num_joints();
  const int S = regs.num_slots();
  CHECK(joint_state.size() == 0 || joint_state.size() == K);
  CHECK_EQ(regs.slot_basis.rows(), S);
  CHECK_EQ(regs.slot_basis.cols(), K);
  CHECK(regs.values.size() == 0 || regs.values.cols() == N) << "regressors of other data";
  const bool blocks = !gradient_only;
  const int FS = blocks ? F + S : F;  // SlotSums::H
  NormalEquations lin;
  lin.H.setZero(P, P);
  lin.g.setZero(P);
  lin.joint_blocks = blocks;
  const BasisJacobian bj(model, p);
  // bj writes the frame columns only (the first F).
  Eigen::VectorXd theta_slots;
  if (joint_state.size() > 0) theta_slots = regs.slot_basis * joint_state;

  const RowChunks chunks = PartitionRows(N, kMinChunkPoses, kMaxChunks);
  std::vector<SlotSums> sums(chunks.chunks);
  const int threads = N < kMinPosesForThreads ? 1 : ThreadsFor(chunks.chunks);
  FourRowPlan plan;
  if (m == 3 && four_rows) plan = MakeFourRowPlan(model, p, true);
  const bool four = plan.ok;
  std::vector<SlotScratch4> scratch4(four ? threads : 0);
  for (SlotScratch4& s : scratch4) {
    s.group = std::min(kSlotGroupPoses, (N + kBlockPoses - 1) / kBlockPoses * kBlockPoses);
    s.A.setZero(3 * kBlockPoses, F + 1 + n);
    s.q_eff.assign(static_cast<size_t>(n) * (kBlockPoses + 4), 0.0);
    s.sin_q.assign(s.q_eff.size(), 0.0);
    s.cos_q.assign(s.q_eff.size(), 0.0);
    if (regs.values.size() == 0) s.V.resize(S, s.group);
    if (joint_state.size() > 0) s.dq.resize(n, s.group);
    s.h.resize(s.group, n);
    if (blocks) {
      s.G.resize(s.group, n * (n + 1) / 2);
      s.C.resize(s.group, static_cast<Eigen::Index>(n) * F);
      s.VT.resize(s.group, S);
    }
  }
  lin.four_rows = four;
  std::vector<SlotScratch> scratch(four ? 0 : threads);
  for (SlotScratch& s : scratch) {
    s.A.resize(static_cast<Eigen::Index>(m) * kBlockPoses, blocks ? std::max(P, F + S) : P);
    s.Y.resize(static_cast<Eigen::Index>(m) * kBlockPoses);
    s.frames.resize(n + 1);
    s.J_q.resize(m, n);
    s.q_eff.resize(n);
    s.h.resize(n);
    if (regs.values.size() == 0) s.V.resize(S, kBlockPoses);
  }
  ForEachTask(chunks.chunks, threads, [&](int c, int thread) {
    SlotSums& cs = sums[c];
    cs.H.setZero(FS, FS);
    cs.g.setZero(F);
    cs.gs.setZero(S);
    if (four) {
      cs.Hfy.setZero(F + 1, F + 1);
      AccumulateSlots4(model, plan, p, theta_slots, regs, blocks, data, chunks.begin(c),
                       chunks.end(c), &scratch4[thread], &cs);
      return;
    }
    AccumulateSlots(kind, bj, p, theta_slots, regs, blocks, data, chunks.begin(c), chunks.end(c),
                    &scratch[thread], &cs);
  });
  Eigen::MatrixXd Hall = Eigen::MatrixXd::Zero(FS, FS);
  Eigen::VectorXd gs = Eigen::VectorXd::Zero(S);
  double sum_error = 0;
  for (const SlotSums& cs : sums) {
    Hall += cs.H;
    if (four) {
      Hall.topLeftCorner(F, F) += cs.Hfy.topLeftCorner(F, F);
      lin.g.head(F) += cs.Hfy.row(F).head(F).transpose();
    }
    lin.g.head(F) += cs.g;
    gs += cs.gs;
    lin.cost += cs.cost;
    lin.max_error = std::max(lin.max_error, cs.max_error);
    sum_error += cs.sum_error;
  }
  Hall.triangularView<Eigen::StrictlyUpper>() = Hall.transpose();
  lin.H.topLeftCorner(F, F) = Hall.topLeftCorner(F, F);
  MapSlotSumsToJointBlocks(Hall, gs, regs, p, blocks, &lin);
  lin.mean_error = data.empty() ? 0.0 : sum_error / data.size();
  lin.finite = std::isfinite(lin.cost) && AllFinite(lin.H) && AllFinite(lin.g);
  return lin;
}

}  // namespace

NormalEquations NormalEquationsOf(const RobotModel& model, const MeasurementSet& data,
                                  const Parameterization& p, const Eigen::VectorXd& joint_state,
                                  const NormalEquationsOptions& options) {
  const bool use_orientation = options.use_orientation, stack = options.stack;
  const double orientation_weight = options.orientation_weight;
  const JointColumnsOptions& joint = options.joint;
  const Eigen::MatrixXd* joint_rows = options.joint_rows;
  PositionErrorRows* errors = options.errors;
  // A block kind's columns change with the state (block_kind.h): its solve takes the dense rows.
  if (p.num_joint_parameters() > 0 && !stack && !joint.dense && !HasNonlinearBlocks(p)) {
    JointSpaceRegressors local;
    const JointSpaceRegressors* regs = joint.regressors;
    if (regs == nullptr) {
      local = BuildJointSpaceRegressors(p, data);
      regs = &local;
    }
    // The rows' measurement kind (measurement_kind_dispatch.h), once per solve: each branch is
    // the kind's inlined Linearize in the loop over the rows.
    return VisitTrackerKind(TrackerKindId(use_orientation), [&](auto tag) {
      using Kind = typename decltype(tag)::type;
      return AccumulateStructured(Kind::Make(1.0, orientation_weight), model, data, p,
                                  joint_state, *regs, joint.gradient_only, joint.four_rows);
    });
  }
  return VisitTrackerKind(TrackerKindId(use_orientation), [&](auto tag) {
    using Kind = typename decltype(tag)::type;
    return Accumulate(Kind::Make(1.0, orientation_weight), model, data, p, joint_state, stack,
                      joint_rows, errors);
  });
}

Eigen::MatrixXd JointRegressorRows(const Parameterization& p, const MeasurementSet& data) {
  const int K = p.num_joint_parameters();
  const int n = data.num_joints();
  const double bytes = 8.0 * n * K * static_cast<double>(data.size());
  if (K == 0 || bytes > kMaxJointRowsBytes) return Eigen::MatrixXd();
  Eigen::MatrixXd rows(n, static_cast<Eigen::Index>(K) * data.size());
  JointTermColumns columns(p, n, K);
  Eigen::MatrixXd R(n, K);
  for (int r = 0; r < data.size(); ++r) {
    columns.Evaluate(r, data.q(r), &R);
    rows.middleCols(static_cast<Eigen::Index>(r) * K, K) = R;
  }
  return rows;
}

}  // namespace internal
}  // namespace lpoe
