// Measurement planning with an error the model cannot explain (lpoe/planning.h
// UnmodelledPlanning, docs/planning.md "Unmodelled error"): the predicted held-out error of a plan
// with the unmodelled error's bias on the calibration, and an exchange that lowers it.
#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include <Eigen/Cholesky>

#include "lpoe/parallel.h"
#include "lpoe/planning.h"

namespace lpoe {
namespace {

constexpr double kInfinity = std::numeric_limits<double>::infinity();

}  // namespace

// Kept per thread so that evaluating a candidate allocates nothing (the exchange evaluates
// thousands, each with P x P matrices of the same size); every product writes the same values in
// the same order as the temporaries it replaces.
struct UnmodelledPlanning::Scratch {
  Eigen::MatrixXd rows, other;     // (at least) a candidate's rows x P
  Eigen::MatrixXd M, H, G;         // a candidate's plan (P x P)
  Eigen::MatrixXd Ms, A, LA, ALA;  // Total's (P x P)
  Eigen::VectorXd d;
  Eigen::LLT<Eigen::MatrixXd> llt;
};

UnmodelledPlanning::Scratch UnmodelledPlanning::NewScratch() const {
  int max_rows = 0;
  for (int c = 0; c < pool_.size(); ++c) max_rows = std::max(max_rows, pool_.rows(c));
  Scratch s;
  s.rows.resize(max_rows, pool_.num_parameters);
  s.other.resize(max_rows, pool_.num_parameters);
  return s;
}

UnmodelledPlanning::UnmodelledPlanning(const PlanningModel& pm, const CandidatePool& pool,
                                       const std::vector<double>& workspace,
                                       const Eigen::MatrixXd& L,
                                       const UnmodelledErrorModel& unmodelled, double sigma,
                                       int max_workspace)
    : pool_(pool), L_(L), u_(unmodelled), sigma2_(sigma * sigma),
      s2_(unmodelled.std * unmodelled.std) {
  const int n = pool.num_joints, P = pool.num_parameters;
  inv_l_ = Eigen::VectorXd::Zero(n);
  for (int j = 0; j < n && j < u_.length_scales.size(); ++j) {
    inv_l_(j) = std::isfinite(u_.length_scales(j)) && u_.length_scales(j) > 0
                    ? 1.0 / u_.length_scales(j)
                    : 0.0;
  }
  R_ = Eigen::MatrixXd::Zero(pool.J.rows(), P);
  if (s2_ == 0 || n == 0) return;
  // R_c = mean over the workspace poses w and tools t' of C_{c,wt'} J_wt': per workspace pose the
  // rows of every tool, and their sum over the tools (the part rho shares between tools).
  const int T = pm.model().num_tools();
  const int W = std::min(max_workspace, static_cast<int>(workspace.size() / std::max(1, n)));
  if (W < 1) return;
  std::vector<int> all_tools(T);
  for (int t = 0; t < T; ++t) all_tools[t] = t;
  std::vector<Eigen::MatrixXd> Jw(W);  // 3T x P
  std::vector<Eigen::MatrixXd> Sw(W);  // 3 x P: sum over the tools
  for (int w = 0; w < W; ++w) {
    pm.Rows(workspace.data() + static_cast<size_t>(w) * n, all_tools, &Jw[w]);
    Sw[w] = Eigen::MatrixXd::Zero(3, P);
    for (int t = 0; t < T; ++t) Sw[w] += Jw[w].middleRows(3 * t, 3);
  }
  const double rho = u_.tool_correlation;
  const double scale = 1.0 / (static_cast<double>(W) * T);
  ForEachTask(pool.size(), ThreadsFor(pool.size()), [&](int c, int /*thread*/) {
    const double* qc = pool.q.data() + static_cast<size_t>(c) * n;
    Eigen::MatrixXd shared = Eigen::MatrixXd::Zero(3, P);
    std::vector<Eigen::MatrixXd> own(pool.visible[c].size(), Eigen::MatrixXd::Zero(3, P));
    for (int w = 0; w < W; ++w) {
      const double k = PoseCorrelation(qc, workspace.data() + static_cast<size_t>(w) * n);
      if (k < 1e-12) continue;
      shared += k * Sw[w];
      for (size_t i = 0; i < pool.visible[c].size(); ++i) {
        own[i] += k * Jw[w].middleRows(3 * pool.visible[c][i], 3);
      }
    }
    for (size_t i = 0; i < pool.visible[c].size(); ++i) {
      R_.middleRows(pool.row_offset[c] + 3 * static_cast<int>(i), 3) =
          scale * (rho * shared + (1 - rho) * own[i]);
    }
  });
}

double UnmodelledPlanning::PoseCorrelation(const double* qa, const double* qb) const {
  double d2 = 0;
  for (int j = 0; j < inv_l_.size(); ++j) {
    const double d = (qa[j] - qb[j]) * inv_l_(j);
    d2 += d * d;
  }
  return std::exp(-0.5 * d2);
}

bool UnmodelledPlanning::CorrelatedRows(int a, int b, Eigen::MatrixXd* out) const {
  const int n = pool_.num_joints;
  const double k = PoseCorrelation(pool_.q.data() + static_cast<size_t>(a) * n,
                                   pool_.q.data() + static_cast<size_t>(b) * n);
  if (k < 1e-12) return false;
  auto rows = out->topRows(pool_.rows(a));
  rows.setZero();
  const std::vector<int>& ta = pool_.visible[a];
  const std::vector<int>& tb = pool_.visible[b];
  for (size_t i = 0; i < ta.size(); ++i) {
    for (size_t j = 0; j < tb.size(); ++j) {
      const double f = ta[i] == tb[j] ? 1.0 : u_.tool_correlation;
      rows.middleRows(3 * i, 3) += k * f * pool_.J.middleRows(pool_.row_offset[b] + 3 * j, 3);
    }
  }
  return true;
}

double UnmodelledPlanning::Total(const Eigen::MatrixXd& M, const Eigen::MatrixXd& H,
                                 const Eigen::MatrixXd& G, Scratch* scratch,
                                 PlanErrorPrediction* out) const {
  const int P = static_cast<int>(M.rows());
  Scratch& sc = *scratch;
  // A = M^-1 with Jacobi scaling (columns of rotations carry lever arms of a metre).
  sc.d = M.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  sc.Ms.noalias() = sc.d.asDiagonal() * M * sc.d.asDiagonal();
  sc.llt.compute(sc.Ms);
  PlanErrorPrediction p;
  if (sc.llt.info() != Eigen::Success) {
    if (out != nullptr) *out = p;
    return kInfinity;
  }
  sc.A.setIdentity(P, P);
  sc.llt.solveInPlace(sc.A);
  sc.A = sc.d.asDiagonal() * sc.A * sc.d.asDiagonal();  // coefficient-wise: no aliasing
  const Eigen::MatrixXd& A = sc.A;
  const double noise = sigma2_ * L_.cwiseProduct(A).sum();
  double unmodelled = 0;
  if (s2_ > 0) {
    sc.LA.noalias() = A * L_;
    sc.ALA.noalias() = sc.LA * A;
    unmodelled =
        s2_ * (sc.ALA.cwiseProduct(H).sum() - 2 * A.cwiseProduct(G.transpose()).sum() + 3);
    unmodelled = std::max(0.0, unmodelled);
  }
  p.noise_rms = std::sqrt(std::max(0.0, noise));
  p.unmodelled_rms = std::sqrt(unmodelled);
  p.total_rms = std::sqrt(std::max(0.0, noise) + unmodelled);
  if (out != nullptr) *out = p;
  return noise + unmodelled;
}

PlanErrorPrediction UnmodelledPlanning::Predict(const std::vector<int>& selected) const {
  const int P = pool_.num_parameters;
  Scratch sc = NewScratch();
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(P, P), H = M, G = M;
  for (int a : selected) {
    const auto Ja = pool_.J.middleRows(pool_.row_offset[a], pool_.rows(a));
    M.noalias() += Ja.transpose() * Ja;
    if (s2_ > 0) {
      G.noalias() += Ja.transpose() * R_.middleRows(pool_.row_offset[a], pool_.rows(a));
      // H = sum over a of J_a^T Y_a, Y_a = sum over b of C_{a,b} J_b: one product per pose.
      auto Ya = sc.other.topRows(pool_.rows(a));
      Ya.setZero();
      for (int b : selected) {
        if (CorrelatedRows(a, b, &sc.rows)) Ya += sc.rows.topRows(pool_.rows(a));
      }
      H.noalias() += Ja.transpose() * Ya;
    }
  }
  PlanErrorPrediction out;
  Total(M, H, G, &sc, &out);
  return out;
}

int UnmodelledPlanning::Exchange(std::vector<int>* selected, int max_passes, int shortlist,
                                 uint64_t seed) const {
  const int P = pool_.num_parameters, N = pool_.size();
  std::vector<int>& plan = *selected;
  std::vector<char> in_plan(N, 0);
  for (int c : plan) in_plan[c] = 1;
  if (static_cast<int>(plan.size()) >= N) return 0;
  auto rows_of = [&](int c) { return pool_.J.middleRows(pool_.row_offset[c], pool_.rows(c)); };
  auto r_of = [&](int c) { return R_.middleRows(pool_.row_offset[c], pool_.rows(c)); };
  // The plan's M, H, G and, for every candidate x, Y_x = sum over the plan of C_{x,s} J_s.
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(P, P), H = M, G = M;
  Eigen::MatrixXd Y = Eigen::MatrixXd::Zero(pool_.J.rows(), P);
  std::vector<Scratch> scratch(std::max(ThreadsFor(N), ThreadsFor(shortlist)));
  for (Scratch& sc : scratch) sc = NewScratch();
  auto add_to_y = [&](int s, double sign) {
    if (s2_ == 0) return;
    ForEachTask(N, ThreadsFor(N), [&](int x, int thread) {
      Eigen::MatrixXd& rows = scratch[thread].rows;
      if (CorrelatedRows(x, s, &rows)) {
        Y.middleRows(pool_.row_offset[x], pool_.rows(x)) += sign * rows.topRows(pool_.rows(x));
      }
    });
  };
  for (int s : plan) {
    M.noalias() += rows_of(s).transpose() * rows_of(s);
    G.noalias() += rows_of(s).transpose() * r_of(s);
    add_to_y(s, 1.0);
  }
  for (int s : plan) {
    H.noalias() += rows_of(s).transpose() * Y.middleRows(pool_.row_offset[s], pool_.rows(s));
  }
  double current = Total(M, H, G, &scratch[0], nullptr);
  std::mt19937_64 rng(seed);
  std::uniform_int_distribution<int> pick(0, N - 1);
  int swaps = 0;
  for (int pass = 0; pass < max_passes; ++pass) {
    int pass_swaps = 0;
    for (size_t i = 0; i < plan.size(); ++i) {
      const int s = plan[i];
      const auto Js = rows_of(s);
      const Eigen::MatrixXd Ys = Y.middleRows(pool_.row_offset[s], pool_.rows(s));
      Eigen::MatrixXd H_without = H - Js.transpose() * Ys - Ys.transpose() * Js;
      if (CorrelatedRows(s, s, &scratch[0].rows)) {  // C_{s,s}: always (correlation 1)
        H_without.noalias() += Js.transpose() * scratch[0].rows.topRows(pool_.rows(s));
      }
      const Eigen::MatrixXd M_without = M - Js.transpose() * Js;
      const Eigen::MatrixXd G_without = G - Js.transpose() * r_of(s);
      // The shortlist: distinct candidates outside the plan.
      std::vector<int> list;
      for (int tries = 0; static_cast<int>(list.size()) < shortlist && tries < 20 * shortlist;
           ++tries) {
        const int c = pick(rng);
        if (!in_plan[c] && std::find(list.begin(), list.end(), c) == list.end()) {
          list.push_back(c);
        }
      }
      std::vector<double> totals(list.size(), kInfinity);
      ForEachTask(static_cast<int>(list.size()), ThreadsFor(static_cast<int>(list.size())),
                  [&](int k, int thread) {
                    const int c = list[k];
                    const int rc = pool_.rows(c);
                    const auto Jc = rows_of(c);
                    Scratch& sc = scratch[thread];
                    sc.M = M_without;
                    sc.M.noalias() += Jc.transpose() * Jc;
                    sc.H = H_without;
                    sc.G = G_without;
                    if (s2_ > 0) {
                      // Y_c without the removed member s: Y_c - C_{c,s} J_s.
                      auto Yc = sc.other.topRows(rc);
                      Yc = Y.middleRows(pool_.row_offset[c], rc);
                      if (CorrelatedRows(c, s, &sc.rows)) Yc -= sc.rows.topRows(rc);
                      sc.H.noalias() += Jc.transpose() * Yc;
                      sc.H.noalias() += Yc.transpose() * Jc;
                      if (CorrelatedRows(c, c, &sc.rows)) {
                        sc.H.noalias() += Jc.transpose() * sc.rows.topRows(rc);
                      }
                      sc.G.noalias() += Jc.transpose() * r_of(c);
                    }
                    totals[k] = Total(sc.M, sc.H, sc.G, &sc, nullptr);
                  });
      int best = -1;
      for (size_t k = 0; k < list.size(); ++k) {
        if (totals[k] < current * (1 - 1e-9) && (best < 0 || totals[k] < totals[best])) {
          best = static_cast<int>(k);
        }
      }
      if (best < 0) continue;
      const int c = list[best];
      // Accept: the plan, M, G, Y (for every candidate) and H recomputed from Y.
      const auto Jc = rows_of(c);
      M = M_without + Jc.transpose() * Jc;
      G = G_without + Jc.transpose() * r_of(c);
      plan[i] = c;
      in_plan[s] = 0;
      in_plan[c] = 1;
      add_to_y(s, -1.0);
      add_to_y(c, 1.0);
      H.setZero();
      for (int t : plan) {
        H.noalias() += rows_of(t).transpose() * Y.middleRows(pool_.row_offset[t], pool_.rows(t));
      }
      current = Total(M, H, G, &scratch[0], nullptr);
      ++pass_swaps;
    }
    swaps += pass_swaps;
    if (pass_swaps == 0) break;
  }
  return swaps;
}

}  // namespace lpoe
