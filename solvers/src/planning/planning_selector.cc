// Measurement planning, the selector (lpoe/planning.h): the criteria, the greedy selection and
// exchange with rank-r updates of the information matrix, evaluation and random plans.
#include "lpoe/planning.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <memory>
#include <numeric>
#include <random>
#include <sstream>
#include <string>
#include <utility>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <glog/logging.h>

#include "identifiability/identifiability.h"
#include "model/level3_workspace.h"
#include "planning/planning_internal.h"
#include "lpoe/analysis.h"
#include "lpoe/kinematics/eigen_decompositions.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/linear_solver.h"
#include "lpoe/measurements/measurements.h"
#include "lpoe/parallel.h"

namespace lpoe {
using planning_internal::kInf;
using planning_internal::kRegularization;

namespace {

// Log-determinant of a symmetric positive definite matrix; -inf when it is not.
double LogDetSpd(const Eigen::MatrixXd& M) {
  Eigen::LLT<Eigen::MatrixXd> llt(M);
  if (llt.info() != Eigen::Success) return -kInf;
  const Eigen::VectorXd d = llt.matrixLLT().diagonal();
  double s = 0;
  for (int k = 0; k < d.size(); ++k) {
    if (!(d(k) > 0)) return -kInf;
    s += 2.0 * std::log(d(k));
  }
  return s;
}

// Cholesky factorization of the r x r column-major matrix a in place (lower triangle); false when
// it is not positive definite. For the small blocks of one candidate, without allocation.
bool CholeskyInPlace(double* a, int r) {
  for (int j = 0; j < r; ++j) {
    double d = a[j + j * r];
    for (int k = 0; k < j; ++k) d -= a[j + k * r] * a[j + k * r];
    if (!(d > 0)) return false;
    d = std::sqrt(d);
    a[j + j * r] = d;
    for (int i = j + 1; i < r; ++i) {
      double v = a[i + j * r];
      for (int k = 0; k < j; ++k) v -= a[i + k * r] * a[j + k * r];
      a[i + j * r] = v / d;
    }
  }
  return true;
}

double MinEigenvalue(const Eigen::MatrixXd& M) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(M, Eigen::EigenvaluesOnly);
  return eig.eigenvalues()(0);
}

// Pool scaling D: 1 / sqrt(mean over candidates of |column j|^2).
Eigen::VectorXd PoolScale(const CandidatePool& pool) {
  const int P = pool.num_parameters;
  Eigen::VectorXd d(P);
  const double n = std::max(1, pool.size());
  for (int j = 0; j < P; ++j) {
    const double mean = pool.J.col(j).squaredNorm() / n;
    d(j) = mean > 0 ? 1.0 / std::sqrt(mean) : 1.0;
  }
  return d;
}

// A symmetric positive semi-definite W as F F^T (F = V sqrt(Lambda)).
Eigen::MatrixXd PsdFactor(const Eigen::MatrixXd& W) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(W);
  return eig.eigenvectors() * eig.eigenvalues().cwiseMax(0.0).cwiseSqrt().asDiagonal();
}

enum class Objective { kLogDet, kTrace, kMinEigen };

using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// Candidates per chunk of the parallel loops, and the fewest candidates worth a second thread.
constexpr int kChunk = 256;
constexpr int kMinCandidatesForThreads = 1000;

// Calls fn(begin, end) over [0, n) in fixed chunks of kChunk on up to `max_threads` threads (0: the
// hardware's). fn must write only the entries of its own chunk, computed from its own data alone:
// the results are then the same, bit for bit, whatever the number of threads.
// The threads of ForEachChunk(n, max_threads, ...).
int ChunkThreads(int n, int max_threads) {
  const int chunks = (n + kChunk - 1) / kChunk;
  return n < kMinCandidatesForThreads
             ? 1
             : (max_threads > 0 ? std::min(max_threads, chunks) : ThreadsFor(chunks));
}

// As ForEachChunk, calling fn(begin, end, thread) with the index of the thread running the chunk
// (below ChunkThreads(n, max_threads)), for scratch space kept per thread.
template <typename Fn>
void ForEachChunkOnThread(int n, int max_threads, const Fn& fn) {
  const int chunks = (n + kChunk - 1) / kChunk;
  ForEachTask(chunks, ChunkThreads(n, max_threads),
              [&](int k, int thread) { fn(k * kChunk, std::min(n, (k + 1) * kChunk), thread); });
}

template <typename Fn>
void ForEachChunk(int n, int max_threads, const Fn& fn) {
  ForEachChunkOnThread(n, max_threads, [&](int begin, int end, int) { fn(begin, end); });
}

// The greedy / exchange state, in pool-scaled coordinates: M = delta I + sum of the plan's J^T J,
// A = M^-1, and for every candidate c: S_c = J_c A J_c^T (its prediction variance, Fedorov's d(c))
// and, for the trace criteria, Z_c = J_c A F with W = F F^T the trace weight. (Keeping
// T_c = Z_c Z_c^T instead would be cheaper but squares the cancellation of the updates while M is
// still dominated by delta I.) The rows J and Z are stored row-major so that a candidate's block
// is contiguous and read once per update; the per-candidate work runs in parallel chunks.
class Selector {
 public:
  Selector(const CandidatePool& pool, const Eigen::VectorXd& scale, Objective objective,
           const Eigen::MatrixXd& weight, int num_threads, const Eigen::MatrixXd& prior)
      : pool_(pool), objective_(objective), P_(pool.num_parameters), num_threads_(num_threads) {
    Js_ = pool.J * scale.asDiagonal();
    if (objective_ == Objective::kTrace) {
      W_ = weight;
      F_ = PsdFactor(weight);
    }
    max_rows_ = 0;
    for (int c = 0; c < pool.size(); ++c) max_rows_ = std::max(max_rows_, pool.rows(c));
    M_ = kRegularization * Eigen::MatrixXd::Identity(P_, P_);
    A_ = Eigen::MatrixXd::Identity(P_, P_) / kRegularization;
    if (prior.rows() == P_) {  // the posterior: the plan's information added to the prior's
      M_ += scale.asDiagonal() * prior * scale.asDiagonal();
      A_ = M_.llt().solve(Eigen::MatrixXd::Identity(P_, P_));
    }
    in_plan_.assign(pool.size(), 0);
  }

  bool in_plan(int c) const { return in_plan_[c] != 0; }

  // The criterion to maximize at the current M.
  double Value() const {
    switch (objective_) {
      case Objective::kLogDet:
        return LogDetSpd(M_);
      case Objective::kTrace:
        return -(W_.cwiseProduct(A_)).sum();
      case Objective::kMinEigen:
        return MinEigenvalue(M_);
    }
    return 0;
  }

  // Improvement of the criterion when candidate c is added (greedy; from the maintained S, T):
  // log det(I + S_c), or trace((I + S_c)^-1 Z_c Z_c^T). `scratch`: 2 r^2 + P doubles.
  double AddGain(int c, double* scratch) const {
    const int r = pool_.rows(c);
    const int o = pool_.row_offset[c];
    double* K = scratch;
    for (int j = 0; j < r; ++j) {
      for (int i = 0; i < r; ++i) K[i + j * r] = S_(o + i, j) + (i == j ? 1.0 : 0.0);
    }
    if (!CholeskyInPlace(K, r)) return -kInf;
    if (objective_ == Objective::kTrace) {
      // |C^-1 Z_c|_F^2 with K = C C^T: invert the r x r factor, then each row of C^-1 Z_c is a
      // combination of the contiguous rows of Z_c (vectorized over P, no division in the loop).
      double* Ci = scratch + r * r;  // lower triangle of C^-1, column-major
      for (int j = 0; j < r; ++j) {
        Ci[j + j * r] = 1.0 / K[j + j * r];
        for (int i = j + 1; i < r; ++i) {
          double v = 0;
          for (int k = j; k < i; ++k) v -= K[i + k * r] * Ci[k + j * r];
          Ci[i + j * r] = v / K[i + i * r];
        }
      }
      Eigen::Map<Eigen::RowVectorXd> y(scratch + 2 * r * r, P_);
      double sum = 0;
      for (int i = 0; i < r; ++i) {
        y = Ci[i] * Z_.row(o);
        for (int k = 1; k <= i; ++k) y += Ci[i + k * r] * Z_.row(o + k);
        sum += y.squaredNorm();
      }
      return sum;
    }
    double logdet = 0;
    for (int i = 0; i < r; ++i) logdet += 2.0 * std::log(K[i + i * r]);
    return logdet;
  }

  // M <- M + J_b^T J_b and A <- M^-1 by the rank-r update, leaving S and Z stale (call Resync()).
  void AddOnly(int b) {
    const auto Jb = Js_.middleRows(pool_.row_offset[b], pool_.rows(b));
    const Eigen::MatrixXd U = A_ * Jb.transpose();
    Eigen::MatrixXd K = Jb * U;
    K.diagonal().array() += 1.0;
    A_.noalias() -= U * K.llt().solve(U.transpose());
    M_.noalias() += Jb.transpose() * Jb;
    in_plan_[b] = 1;
  }

  // Prepares SwapValue for plan member s: u = A J_s^T.
  void PrepareRemoval(int s) {
    removal_ = s;
    u_ = A_ * Js_.middleRows(pool_.row_offset[s], pool_.rows(s)).transpose();
  }

  // The criterion after swapping the prepared plan member s for candidate c (from the maintained S
  // and Z, exact up to their round-off).
  double SwapValue(int c, double current) const {
    const int s = removal_;
    const int rs = pool_.rows(s), rc = pool_.rows(c);
    const int os = pool_.row_offset[s], oc = pool_.row_offset[c];
    if (objective_ == Objective::kMinEigen) {
      const auto Jc = Js_.middleRows(oc, rc);
      const auto Jsb = Js_.middleRows(os, rs);
      Eigen::MatrixXd M = M_;
      M.noalias() += Jc.transpose() * Jc;
      M.noalias() -= Jsb.transpose() * Jsb;
      return MinEigenvalue(M);
    }
    // M' = M + B^T Sigma B, B = [J_c; J_s], Sigma = diag(I, -I); G = B A B^T from S and u.
    const int m = rc + rs;
    Eigen::MatrixXd G(m, m);
    G.topLeftCorner(rc, rc) = S_.block(oc, 0, rc, rc);
    G.bottomRightCorner(rs, rs) = S_.block(os, 0, rs, rs);
    G.topRightCorner(rc, rs).noalias() = Js_.middleRows(oc, rc).lazyProduct(u_);
    G.bottomLeftCorner(rs, rc) = G.topRightCorner(rc, rs).transpose();
    if (objective_ == Objective::kLogDet) {
      // det M' / det M = det(I + Sigma G).
      G.bottomRows(rs) *= -1.0;
      G.diagonal().array() += 1.0;
      const double det = G.partialPivLu().determinant();
      return det > 0 ? current + std::log(det) : -kInf;
    }
    // trace(W A') = trace(W A) - trace((Sigma + G)^-1 B A W A B^T), B A F = [Z_c; Z_s].
    G.diagonal().head(rc).array() += 1.0;
    G.diagonal().tail(rs).array() -= 1.0;
    Eigen::MatrixXd Zb(m, P_);
    Zb.topRows(rc) = Z_.middleRows(oc, rc);
    Zb.bottomRows(rs) = Z_.middleRows(os, rs);
    return current + G.partialPivLu().solve(Zb * Zb.transpose()).trace();
  }

  // M <- M + sign J_b^T J_b for candidate b, with the rank-r updates of A, S and Z:
  // U = A J_b^T, K = sign I + J_b U, A <- A - U K^-1 U^T, and per candidate c with V_c = J_c U:
  // S_c <- S_c - V_c K^-1 V_c^T, Z_c <- Z_c - V_c K^-1 U^T F (one product per chunk).
  void Update(int b, double sign) {
    const int r = pool_.rows(b);
    const auto Jb = Js_.middleRows(pool_.row_offset[b], r);
    const Eigen::MatrixXd U = A_ * Jb.transpose();  // P x r
    Eigen::MatrixXd K = Jb * U;
    K.diagonal().array() += sign;  // (sign I)^-1 = sign I
    const Eigen::MatrixXd Kinv = K.partialPivLu().inverse();
    A_.noalias() -= U * Kinv * U.transpose();
    M_.noalias() += sign * (Jb.transpose() * Jb);
    in_plan_[b] = sign > 0;
    const bool trace = objective_ == Objective::kTrace;
    Eigen::MatrixXd UtF;
    if (trace) UtF = U.transpose() * F_;  // r x P
    const size_t threads = ChunkThreads(pool_.size(), num_threads_);
    if (chunk_scratch_.size() < threads) chunk_scratch_.resize(threads);
    ForEachChunkOnThread(pool_.size(), num_threads_, [&](int begin, int end, int thread) {
      // The chunk's rows against U and Kinv as two matrix products (blocked and vectorized), not a
      // small lazy product per candidate; only each candidate's own r_c x r_c block of S is formed.
      // The products and their packing buffers are kept per thread between updates (hundreds per
      // plan, each of the same sizes; level3_workspace.h, the same results bit for bit).
      const int o = pool_.row_offset[begin];
      const int rows = pool_.row_offset[end] - o;
      ChunkScratch& scratch = chunk_scratch_[thread];
      scratch.level3.Product(Js_.middleRows(o, rows), U, &scratch.V);  // rows x r
      scratch.level3.Product(scratch.V, Kinv, &scratch.VK);
      const Eigen::MatrixXd& V = scratch.V;
      const Eigen::MatrixXd& VK = scratch.VK;
      // S_c -= VK_c V_c^T: r_c x r_c entries of r-long dot products (r, r_c <= 6), as plain loops:
      // an Eigen product expression per candidate cost more to set up than these few multiply-adds.
      for (int c = begin; c < end; ++c) {
        const int oc = pool_.row_offset[c];
        const int rc = pool_.rows(c);
        for (int i = 0; i < rc; ++i) {
          for (int j = 0; j < rc; ++j) {
            double sum = 0;
            for (int k = 0; k < r; ++k) sum += VK(oc - o + i, k) * V(oc - o + j, k);
            S_(oc + i, j) -= sum;
          }
        }
      }
      if (trace) Z_.middleRows(o, rows).noalias() -= VK * UtF;
    });
  }

  // Recomputes A, S and Z from M (removes the drift of repeated updates).
  void Resync() {
    A_ = M_.llt().solve(Eigen::MatrixXd::Identity(P_, P_));
    const bool trace = objective_ == Objective::kTrace;
    S_.setZero(Js_.rows(), max_rows_);
    Eigen::MatrixXd AF;
    if (trace) {
      Z_.resize(Js_.rows(), P_);
      AF = A_ * F_;
    }
    ForEachChunk(pool_.size(), num_threads_, [&](int begin, int end) {
      const int o = pool_.row_offset[begin];
      const int rows = pool_.row_offset[end] - o;
      const auto Jchunk = Js_.middleRows(o, rows);
      const RowMatrix JA = Jchunk * A_;
      for (int c = begin; c < end; ++c) {
        const int oc = pool_.row_offset[c];
        const int rc = pool_.rows(c);
        S_.block(oc, 0, rc, rc).noalias() =
            JA.middleRows(oc - o, rc).lazyProduct(Js_.middleRows(oc, rc).transpose());
      }
      if (trace) Z_.middleRows(o, rows).noalias() = Jchunk * AF;
    });
  }

  // Ranking for the exchange shortlist: the greedy gain, or for the minimum eigenvalue the
  // candidate's information along the weakest directions of M.
  void Scores(std::vector<double>* score) const {
    score->assign(pool_.size(), -kInf);
    if (objective_ == Objective::kMinEigen) {
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(M_);
      const int k = std::min(3, P_);
      const Eigen::MatrixXd Y = Js_ * eig.eigenvectors().leftCols(k);
      for (int c = 0; c < pool_.size(); ++c) {
        if (!in_plan(c)) (*score)[c] = Y.middleRows(pool_.row_offset[c], pool_.rows(c)).squaredNorm();
      }
      return;
    }
    ForEachChunk(pool_.size(), num_threads_, [&](int begin, int end) {
      std::vector<double> scratch(2 * max_rows_ * max_rows_ + P_);
      for (int c = begin; c < end; ++c) {
        if (!in_plan(c)) (*score)[c] = AddGain(c, scratch.data());
      }
    });
  }

 private:
  const CandidatePool& pool_;
  Objective objective_;
  int P_;
  int num_threads_;
  int max_rows_ = 0;
  RowMatrix Js_;  // scaled rows of every candidate
  Eigen::MatrixXd W_, F_;
  Eigen::MatrixXd M_, A_;
  RowMatrix S_;  // block c at rows [o_c, o_c + r_c), columns [0, r_c)
  RowMatrix Z_;
  std::vector<char> in_plan_;
  int removal_ = -1;
  Eigen::MatrixXd u_;
  // Update's per-thread products and their packing buffers.
  struct ChunkScratch {
    internal::Level3Workspace level3;
    Eigen::MatrixXd V, VK;
  };
  std::vector<ChunkScratch> chunk_scratch_;
};


}  // namespace

const char* PlanCriterionName(PlanCriterion criterion) {
  switch (criterion) {
    case PlanCriterion::kD:
      return "D";
    case PlanCriterion::kA:
      return "A";
    case PlanCriterion::kE:
      return "E";
    case PlanCriterion::kI:
      return "I";
    case PlanCriterion::kO1:
      return "O1";
    case PlanCriterion::kO3:
      return "O3";
  }
  return "?";
}

bool ParsePlanCriterion(const std::string& text, PlanCriterion* criterion) {
  for (PlanCriterion c : {PlanCriterion::kD, PlanCriterion::kA, PlanCriterion::kE, PlanCriterion::kI,
                          PlanCriterion::kO1, PlanCriterion::kO3}) {
    if (text == PlanCriterionName(c)) {
      *criterion = c;
      return true;
    }
  }
  return false;
}


Eigen::MatrixXd Information(const CandidatePool& pool, const std::vector<int>& selected) {
  const int P = pool.num_parameters;
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(P, P);
  for (int c : selected) {
    M.selfadjointView<Eigen::Lower>().rankUpdate(
        pool.J.middleRows(pool.row_offset[c], pool.rows(c)).transpose());
  }
  return M.selfadjointView<Eigen::Lower>();
}

PlanQuality EvaluatePlan(const PlanningModel& pm, const CandidatePool& pool,
                         const std::vector<int>& selected, const Eigen::MatrixXd& workspace_moment,
                         const Eigen::MatrixXd& prior_information) {
  PlanQuality out;
  const int P = pool.num_parameters;
  out.num_poses = static_cast<int>(selected.size());
  for (int c : selected) out.num_rows += pool.rows(c);
  Eigen::MatrixXd M = Information(pool, selected);
  if (prior_information.rows() == P) M += prior_information;
  const internal::Identifiability id = internal::Analyze(M);
  out.rank = id.rank;
  out.condition_number = id.condition;
  out.d = -kInf;
  out.a = kInf;
  out.e = 0;
  out.i = kInf;
  out.o1 = 0;
  out.o3 = 0;
  if (id.rank < P) return out;
  const Eigen::VectorXd d = PoolScale(pool);
  const Eigen::MatrixXd Ms = d.asDiagonal() * M * d.asDiagonal();
  const Eigen::LLT<Eigen::MatrixXd> llt(Ms);
  if (llt.info() != Eigen::Success) return out;
  const Eigen::MatrixXd Ms_inv = llt.solve(Eigen::MatrixXd::Identity(P, P));
  out.d = LogDetSpd(Ms);
  out.a = Ms_inv.trace();
  out.e = MinEigenvalue(Ms);
  // trace(L M^-1) = trace(L_s M_s^-1) with L_s = D L D.
  const Eigen::MatrixXd Ls = d.asDiagonal() * workspace_moment * d.asDiagonal();
  out.i = Ls.cwiseProduct(Ms_inv).sum();
  out.predicted_rms = std::sqrt(std::max(0.0, out.i));
  const Eigen::VectorXd e = pm.ErrorScale();
  const Eigen::MatrixXd Me = e.asDiagonal() * M * e.asDiagonal();
  out.o1 = std::exp(LogDetSpd(Me) / (2.0 * P)) / std::sqrt(static_cast<double>(out.num_rows));
  out.o3 = std::sqrt(std::max(0.0, MinEigenvalue(Me)));
  return out;
}

Status SelectPlan(const PlanningModel& pm, const CandidatePool& pool, int count,
                  const Eigen::MatrixXd& workspace_moment, const PlanOptions& options,
                  PlanResult* result) {
  if (count < 1 || count > pool.size()) {
    return Status::Error("cannot choose " + std::to_string(count) + " poses from " +
                         std::to_string(pool.size()) + " feasible candidates");
  }
  const int P = pool.num_parameters;
  // Each criterion as (objective, scaling, weight) on M.
  Eigen::VectorXd scale = PoolScale(pool);
  Objective objective = Objective::kLogDet;
  Eigen::MatrixXd weight;
  switch (options.criterion) {
    case PlanCriterion::kD:
    case PlanCriterion::kO1:  // a monotone function of det M at fixed N
      break;
    case PlanCriterion::kA:
      objective = Objective::kTrace;
      weight = Eigen::MatrixXd::Identity(P, P);
      break;
    case PlanCriterion::kI:
      objective = Objective::kTrace;
      CHECK_EQ(workspace_moment.rows(), P);
      // trace(L M^-1) = trace(D L D (D M D)^-1).
      weight = scale.asDiagonal() * workspace_moment * scale.asDiagonal();
      // Keep the weight's scale near 1 so that the regularization stays negligible.
      weight /= std::max(weight.trace() / P, 1e-300);
      break;
    case PlanCriterion::kE:
      objective = Objective::kMinEigen;
      break;
    case PlanCriterion::kO3:
      objective = Objective::kMinEigen;
      scale = pm.ErrorScale();
      // Normalize so that one pose still contributes a mean diagonal near 1.
      scale /= std::sqrt((pool.J * scale.asDiagonal()).colwise().squaredNorm().mean() /
                         std::max(1, pool.size()));
      break;
  }

  // Greedy: from an empty plan, add the candidate with the largest gain; every candidate's S_c (and
  // Z_c) follows the plan by rank-r updates, one (rows x P x r) product per step. The
  // minimum-eigenvalue criteria start from the D-greedy plan (lambda_min stays 0 until M has full
  // rank). (Lazy evaluation does not pay here: the gains of a random pool drop together.)
  auto local_owner = std::make_unique<Selector>(
      pool, scale, objective == Objective::kMinEigen ? Objective::kLogDet : objective, weight,
      options.num_threads, options.prior_information);
  local_owner->Resync();
  result->selected.clear();
  std::vector<double> gains;
  int rows = 0;
  bool full_rank_resync = false;
  for (int k = 0; k < count; ++k) {
    if (!full_rank_resync && rows >= P) {  // delta I no longer dominates: drop the round-off
      local_owner->Resync();
      full_rank_resync = true;
    }
    local_owner->Scores(&gains);
    const int best = static_cast<int>(std::max_element(gains.begin(), gains.end()) - gains.begin());
    CHECK(!local_owner->in_plan(best));
    local_owner->Update(best, +1.0);
    result->selected.push_back(best);
    rows += pool.rows(best);
  }

  // Exchange: swap each plan member for the best of the shortlist while the criterion improves.
  if (objective == Objective::kMinEigen) {
    local_owner = std::make_unique<Selector>(pool, scale, objective, weight, options.num_threads,
                                             options.prior_information);
    for (int c : result->selected) local_owner->AddOnly(c);
  }
  Selector& local = *local_owner;
  local.Resync();  // the greedy's updates started from M = delta I: remove their round-off
  result->exchanges = 0;
  result->passes = 0;
  std::vector<double> score;
  std::vector<int> order(pool.size());
  std::vector<int> shortlist;
  const int K = std::min<int>(options.shortlist, pool.size() - count);
  bool stale = true;  // the shortlist is recomputed after every accepted swap
  double current = 0;
  for (int pass = 0; pass < options.max_exchange_passes && K > 0; ++pass) {
    ++result->passes;
    bool improved = false;
    for (int k = 0; k < count; ++k) {
      if (stale) {
        local.Scores(&score);
        std::iota(order.begin(), order.end(), 0);
        std::partial_sort(order.begin(), order.begin() + K, order.end(),
                          [&](int a, int b) { return score[a] > score[b]; });
        shortlist.assign(order.begin(), order.begin() + K);
        current = local.Value();
        stale = false;
      }
      const int s = result->selected[k];
      local.PrepareRemoval(s);
      int best = -1;
      double best_value = current + 1e-9 * std::max(1.0, std::abs(current));
      for (int c : shortlist) {
        if (local.in_plan(c)) continue;
        const double v = local.SwapValue(c, current);
        if (v > best_value) {
          best_value = v;
          best = c;
        }
      }
      if (best < 0) continue;
      local.Update(s, -1.0);
      local.Update(best, +1.0);
      const double value = local.Value();
      if (!(value > current)) {  // round-off of the maintained terms: undo
        local.Update(best, -1.0);
        local.Update(s, +1.0);
        continue;
      }
      result->selected[k] = best;
      ++result->exchanges;
      improved = true;
      stale = true;
    }
    if (!improved) break;
  }
  return Status::Ok();
}

std::vector<int> RandomPlan(int pool_size, int count, uint64_t seed) {
  std::vector<int> order = ShuffledIndices(pool_size, seed);
  order.resize(std::min(count, pool_size));
  return order;
}


}  // namespace lpoe
