// The learned residual layer: kernel, prediction, hyperparameters by the marginal likelihood and
// the sparse posterior (lpoe/model/residual_layer.h, docs/residual_layer.md).
#include "lpoe/model/residual_layer.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <limits>
#include <numeric>
#include <random>
#include <sstream>
#include <utility>

#include <Eigen/Cholesky>
#include <Eigen/Dense>

#include <LBFGSB.h>

#include "lpoe/kinematics/kernels.h"
#include "lpoe/parallel.h"
#include "model/level3_workspace.h"

namespace lpoe {
namespace {

constexpr double kTwoPi = 6.283185307179586476925286766559;
// Added to the diagonal of the exact kernel matrix (relative to s_f^2) and of K_mm.
constexpr double kExactJitter = 1e-8;
constexpr double kInducingJitter = 1e-6;

// Bounds of the hyperparameters (log space): length scales 1e-3..1e6 (rad or mm); the tool's
// 1.2011..10, i.e. rho = exp(-1 / l_tool^2) from 0.5 to 0.99: the signal is at least half shared
// by the SMRs of a configuration. A free rho down to 0 lets the likelihood give each SMR a signal
// of its own, which with short length scales is the rows' noise again (the data fragmented by
// tool, a flat ridge the optimizer wanders along); s_f, s_n and s_c 1e-6..1e3 mm.
constexpr double kLogLengthMin = -6.907755278982137, kLogLengthMax = 13.815510557964274;
constexpr double kLogToolMin = 0.1832564602908322, kLogToolMax = 2.302585092994046;
constexpr double kLogStdMin = -13.815510557964274, kLogStdMax = 6.907755278982137;

// Squared distance in length-scale units between rows a of A and b of B (n joints).
inline double ScaledSquaredDistance(const double* a, const double* b, const double* inv_l, int n) {
  double s = 0;
  for (int j = 0; j < n; ++j) {
    const double d = (a[j] - b[j]) * inv_l[j];
    s += d * d;
  }
  return s;
}

// exp(v[i]) in place for the kernel vector: the prediction's hot spot (m exponentials a point).
// SLEEF's AVX2 exp where the processor has it (kernels::ExpAvx2), else std::exp.
void ExpInPlace(double* v, int count) {
  if (kernels::Avx2Fma()) {
    kernels::ExpAvx2(v, count);
    return;
  }
  for (int i = 0; i < count; ++i) v[i] = std::exp(v[i]);
}

struct Hyper {
  Eigen::VectorXd l;      // length scales
  double rho = 1;         // tool correlation
  double lt = 0;          // tool length scale (with_tool)
  double sf2 = 0, sn2 = 0;
  double sc2 = 0;         // configuration variance (with a configuration list)
};

Hyper Unpack(const Eigen::VectorXd& theta, int n, bool with_tool, bool with_configuration) {
  Hyper h;
  h.l = theta.head(n).array().exp();
  int k = n;
  if (with_tool) {
    h.lt = std::exp(theta(k++));
    h.rho = std::exp(-1.0 / (h.lt * h.lt));
  }
  h.sf2 = std::exp(2 * theta(k++));
  h.sn2 = std::exp(2 * theta(k++));
  if (with_configuration) h.sc2 = std::exp(2 * theta(k));
  return h;
}

// The exact kernel matrix of the hyperparameter rows: K_se (signal part) and K = K_se + s_c^2 on
// rows of one configuration + (s_n^2 + jitter) on the diagonal.
// With `U` (rows x 3: projected observations u_a . m(x_a)), both terms between rows a and b are
// multiplied by u_a . u_b.
void ExactKernel(const Hyper& h, const Eigen::MatrixXd& X, const std::vector<int>& tools,
                 const std::vector<int>* configuration, Eigen::MatrixXd* Kse, Eigen::MatrixXd* K,
                 const Eigen::MatrixXd* U = nullptr) {
  const int N = static_cast<int>(X.rows()), n = static_cast<int>(X.cols());
  // The scaled inputs, a column per row (contiguous).
  const Eigen::MatrixXd Xst = (X * h.l.cwiseInverse().asDiagonal()).transpose();
  Kse->resize(N, N);
  for (int b = 0; b < N; ++b) {
    const double* xb = Xst.col(b).data();
    for (int a = b; a < N; ++a) {
      const double* xa = Xst.col(a).data();
      double d2 = 0;
      for (int j = 0; j < n; ++j) d2 += (xa[j] - xb[j]) * (xa[j] - xb[j]);
      double k = h.sf2 * std::exp(-0.5 * d2);
      if (tools[a] != tools[b]) k *= h.rho;
      if (U != nullptr) k *= U->row(a).dot(U->row(b));
      (*Kse)(a, b) = (*Kse)(b, a) = k;
    }
  }
  *K = *Kse;
  if (configuration != nullptr) {
    for (int b = 0; b < N; ++b) {
      for (int a = 0; a < N; ++a) {
        if ((*configuration)[a] == (*configuration)[b]) {
          (*K)(a, b) += U == nullptr ? h.sc2 : h.sc2 * U->row(a).dot(U->row(b));
        }
      }
    }
  }
  K->diagonal().array() += h.sn2 + kExactJitter * h.sf2;
}

// The N x N matrices of the exact GP's likelihood, kept per thread between evaluations: the fit
// evaluates the likelihood hundreds of times at one size, and allocating megabytes afresh each
// time costs a page fault per page (about a third of the fit's time in the dev build). So are
// the packing buffers of its triangular solves and products (level3_workspace.h): Eigen
// allocated them afresh at every call, the same cost again under AddressSanitizer.
struct GpWorkspace {
  Eigen::MatrixXd Kse, K, Linv, Kinv, A;
  Eigen::LLT<Eigen::MatrixXd> llt;
  internal::Level3Workspace level3;
};

GpWorkspace& ThreadGpWorkspace() {
  thread_local GpWorkspace workspace;
  return workspace;
}

// The lower triangle of K^-1 in *Kinv (its strict upper triangle is not set) from the Cholesky
// factor L of K (the lower triangle of `llt`), by column blocks that skip the zeros: block J of
// L^-1 is zero above its diagonal block (only L[j0:, j0:] enters its solve), and the lower part of
// block J of K^-1 = L^-T L^-1 needs only the rows of L^-1 from j0 on (a triangular product). About
// N^3 / 3 multiply-adds where solving K X = I takes N^3.
void LowerInverseFromCholesky(const Eigen::MatrixXd& llt, Eigen::MatrixXd* Linv,
                              Eigen::MatrixXd* Kinv, internal::Level3Workspace* level3) {
  const Eigen::Index N = llt.rows();
  constexpr Eigen::Index kBlock = 48;
  Linv->setZero(N, N);
  for (Eigen::Index j0 = 0; j0 < N; j0 += kBlock) {
    const Eigen::Index b = std::min(kBlock, N - j0);
    auto block = Linv->block(j0, j0, N - j0, b);
    block.topRows(b).setIdentity();
    // block := L[j0:, j0:]^-1 block
    level3->LowerSolveInPlace(llt.block(j0, j0, N - j0, N - j0), block);
  }
  Kinv->resize(N, N);
  for (Eigen::Index j0 = 0; j0 < N; j0 += kBlock) {
    const Eigen::Index b = std::min(kBlock, N - j0);
    // Kinv[j0:, j0:j0+b] := (L^-1)[j0:, j0:]^T (L^-1)[j0:, j0:j0+b], the transpose upper triangular
    level3->LowerTransposeTimes(Linv->block(j0, j0, N - j0, N - j0),
                                Linv->block(j0, j0, N - j0, b), Kinv->block(j0, j0, N - j0, b));
  }
}

// Minimizes f(x, &gradient) within [lower, upper] by LBFGSpp's L-BFGS-B (Debian's
// liblbfgspp-dev); returns the iterations. LBFGSpp throws when its line search cannot make
// progress (at a minimum to the precision of the objective, or where the objective is not
// finite); then, as always, the best point evaluated is the result, and the count returned is
// that of the objective's evaluations.
template <typename F>
int MinimizeBounded(const F& f, const Eigen::VectorXd& lower, const Eigen::VectorXd& upper,
                    int max_iterations, Eigen::VectorXd* x) {
  LBFGSpp::LBFGSBParam<double> param;
  param.m = 7;
  param.max_iterations = std::max(1, max_iterations);
  param.epsilon = 1e-5;      // projected gradient (the objective is per hyperparameter row)
  param.epsilon_rel = 0;
  param.past = 3;
  param.delta = 1e-7;        // relative decrease of the objective over three iterations
  param.max_linesearch = 40;
  param.max_step = 4.0;      // log space: a factor e^4 per iteration at most
  LBFGSpp::LBFGSBSolver<double> solver(param);
  double best = std::numeric_limits<double>::infinity();
  Eigen::VectorXd best_x = *x;
  int evaluations = 0;
  auto objective = [&](const Eigen::VectorXd& t, Eigen::VectorXd& g) {
    ++evaluations;
    const double v = f(t, &g);
    if (!std::isfinite(v) || !g.allFinite()) {
      g.setZero(t.size());
      return std::numeric_limits<double>::max();
    }
    if (v < best) {
      best = v;
      best_x = t;
    }
    return v;
  };
  int iterations = 0;
  try {
    double fx = 0;
    Eigen::VectorXd start = *x;
    iterations = solver.minimize(objective, start, fx, lower, upper);
  } catch (const std::exception&) {
    iterations = evaluations;  // the line search gave up: the evaluations made
  }
  *x = best_x;
  return iterations;
}

}  // namespace

// ---- Prediction.

void ResidualLayer::KernelVector(const double* q, int tool, Eigen::VectorXd* k) const {
  const int m = num_inducing();
  k->resize(m);
  // Half the squared distance in length-scale units, accumulated in k, then the exponential (both
  // vectorized by Eigen).
  auto e = k->array();
  for (int j = 0; j < num_joints; ++j) {
    const double s = std::sqrt(0.5) / length_scales(j);
    if (j == 0) {
      e = ((inducing_q.col(j).array() - q[j]) * s).square();
    } else {
      e += ((inducing_q.col(j).array() - q[j]) * s).square();
    }
  }
  const double log_sf2 = 2 * std::log(signal_std);
  e = log_sf2 - e;
  ExpInPlace(k->data(), m);
  if (tool_correlation != 1.0) {
    for (int i = 0; i < m; ++i) {
      if (inducing_tool[i] != tool) (*k)(i) *= tool_correlation;
    }
  }
}

Eigen::Vector3d ResidualLayer::Mean(const double* q, int tool, double* dm_dq) const {
  thread_local Eigen::VectorXd k;
  KernelVector(q, tool, &k);
  const Eigen::Vector3d mean = weights.transpose() * k;
  if (dm_dq != nullptr) {
    // dk_i/dq_j = k_i (z_ij - q_j) / l_j^2.
    const Eigen::MatrixXd wk = weights.array().colwise() * k.array();  // m x 3
    for (int j = 0; j < num_joints; ++j) {
      const double inv_l2 = 1.0 / (length_scales(j) * length_scales(j));
      const Eigen::Vector3d col =
          wk.transpose() * ((inducing_q.col(j).array() - q[j]) * inv_l2).matrix();
      dm_dq[3 * j] = col(0);
      dm_dq[3 * j + 1] = col(1);
      dm_dq[3 * j + 2] = col(2);
    }
  }
  return mean;
}

double ResidualLayer::Std(const double* q, int tool) const {
  thread_local Eigen::VectorXd k;
  KernelVector(q, tool, &k);
  const double sf2 = signal_std * signal_std;
  const double v = sf2 - k.dot(variance * k);
  return std::sqrt(std::min(sf2, std::max(0.0, v)));
}

double ResidualLayer::KernelDistance(const double* q) const {
  double best = std::numeric_limits<double>::infinity();
  for (int i = 0; i < num_inducing(); ++i) {
    double s = 0;
    for (int j = 0; j < num_joints; ++j) {
      const double d = (q[j] - inducing_q(i, j)) / length_scales(j);
      s += d * d;
    }
    best = std::min(best, s);
  }
  return std::sqrt(best);
}

Status ResidualLayer::Validate(int model_joints, int model_tools) const {
  std::ostringstream os;
  const int m = num_inducing();
  if (num_joints != model_joints) {
    os << "the residual layer is for " << num_joints << " joints, the model has " << model_joints;
  } else if (num_tools != model_tools) {
    os << "the residual layer is for " << num_tools << " tools, the model has " << model_tools;
  } else if (length_scales.size() != num_joints) {
    os << "the residual layer has " << length_scales.size() << " length scales for " << num_joints
       << " joints";
  } else if (!(length_scales.array() > 0).all() || !length_scales.allFinite()) {
    os << "the residual layer's length scales must be finite and positive";
  } else if (!(tool_correlation >= 0 && tool_correlation <= 1)) {
    os << "the residual layer's tool correlation must be in [0, 1]";
  } else if (!(std::isfinite(signal_std) && signal_std > 0) ||
             !(std::isfinite(noise_std) && noise_std > 0)) {
    os << "the residual layer's signal and noise standard deviations must be finite and positive";
  } else if (m < 1 || inducing_q.cols() != num_joints ||
             static_cast<int>(inducing_tool.size()) != m || weights.rows() != m ||
             weights.cols() != 3 || variance.rows() != m || variance.cols() != m) {
    os << "the residual layer's inducing inputs, tools, weights and variance matrix do not have "
          "matching sizes";
  } else if (!inducing_q.allFinite() || !weights.allFinite() || !variance.allFinite()) {
    os << "the residual layer has non-finite values";
  } else if (!variance.isApprox(variance.transpose(), 1e-12) &&
             (variance - variance.transpose()).cwiseAbs().maxCoeff() >
                 1e-12 * (1 + variance.cwiseAbs().maxCoeff())) {
    os << "the residual layer's variance matrix is not symmetric";
  } else {
    for (int t : inducing_tool) {
      if (t < 0 || t >= num_tools) {
        os << "the residual layer names tool index " << t << " (the model has " << num_tools
           << " tools)";
        break;
      }
    }
  }
  const std::string message = os.str();
  return message.empty() ? Status::Ok() : Status::Error(message);
}

// ---- Marginal likelihood.

namespace internal {

double GpLogMarginalLikelihood(const Eigen::VectorXd& theta, bool with_tool,
                               const Eigen::MatrixXd& X, const std::vector<int>& tools,
                               const Eigen::MatrixXd& Y, Eigen::VectorXd* gradient,
                               const std::vector<int>* configuration, const Eigen::MatrixXd* U) {
  const int N = static_cast<int>(X.rows()), n = static_cast<int>(X.cols());
  const Hyper h = Unpack(theta, n, with_tool, configuration != nullptr);
  GpWorkspace& w = ThreadGpWorkspace();
  ExactKernel(h, X, tools, configuration, &w.Kse, &w.K, U);
  w.llt.compute(w.K);
  if (w.llt.info() != Eigen::Success) return -std::numeric_limits<double>::infinity();
  // A = K^-1 Y (N x 3), as w.llt.solve(Y) computes it: L^-T L^-1 Y.
  w.A = Y;
  w.level3.LowerSolveInPlace(w.llt.matrixLLT(), w.A);
  w.level3.LowerTransposeSolveInPlace(w.llt.matrixLLT(), w.A);
  const Eigen::MatrixXd& A = w.A;
  const int outputs = static_cast<int>(Y.cols());
  double log_det = 0;
  for (int i = 0; i < N; ++i) log_det += 2 * std::log(w.llt.matrixLLT()(i, i));
  const double L = -0.5 * (Y.array() * A.array()).sum() - 0.5 * outputs * log_det -
                   0.5 * outputs * N * std::log(kTwoPi);
  if (gradient == nullptr) return L;
  // dL/dtheta = 1/2 tr(M dK/dtheta), M = A A^T - outputs K^-1: M and dK/dtheta are symmetric, so
  // one pass over the lower triangle, the terms off the diagonal counted twice.
  LowerInverseFromCholesky(w.llt.matrixLLT(), &w.Linv, &w.Kinv, &w.level3);
  const Eigen::MatrixXd At = A.transpose();                                     // 3 x N
  const Eigen::MatrixXd Xst = (X * h.l.cwiseInverse().asDiagonal()).transpose();  // n x N
  const int p = static_cast<int>(theta.size());
  Eigen::VectorXd length_sums = Eigen::VectorXd::Zero(n);
  double tool_sum = 0, mk_sum = 0, configuration_sum = 0, trace_M = 0;
  for (int b = 0; b < N; ++b) {
    const double* xb = Xst.col(b).data();
    const double* ab = At.col(b).data();
    for (int a = b; a < N; ++a) {
      const double* xa = Xst.col(a).data();
      const double* aa = At.col(a).data();
      double m = -outputs * w.Kinv(a, b);
      for (int o = 0; o < outputs; ++o) m += aa[o] * ab[o];
      if (a == b) trace_M += m;
      const double weight = a == b ? 1.0 : 2.0;
      const double mk = weight * m * w.Kse(a, b);
      for (int j = 0; j < n; ++j) {
        const double d = xa[j] - xb[j];
        length_sums(j) += mk * d * d;
      }
      if (with_tool && tools[a] != tools[b]) tool_sum += mk;
      mk_sum += mk;
      if (configuration != nullptr && (*configuration)[a] == (*configuration)[b]) {
        configuration_sum +=
            U == nullptr ? weight * m : weight * m * U->row(a).dot(U->row(b));
      }
    }
  }
  gradient->setZero(p);
  for (int j = 0; j < n; ++j) (*gradient)(j) = 0.5 * length_sums(j);  // dK/dlog l_j = K .* d^2 / l^2
  int k = n;
  if (with_tool) {
    (*gradient)(k++) = 0.5 * tool_sum * 2.0 / (h.lt * h.lt);  // d rho/d log l_t = rho 2 / l_t^2
  }
  (*gradient)(k++) = 0.5 * (2 * mk_sum + trace_M * 2 * kExactJitter * h.sf2);
  (*gradient)(k++) = 0.5 * trace_M * 2 * h.sn2;
  if (configuration != nullptr) (*gradient)(k) = 0.5 * configuration_sum * 2 * h.sc2;
  return L;
}

double GpLeaveOneConfigurationOut(const Eigen::VectorXd& theta, bool with_tool,
                                  const Eigen::MatrixXd& X, const std::vector<int>& tools,
                                  const Eigen::MatrixXd& Y,
                                  const std::vector<int>* configuration, const Eigen::MatrixXd* U) {
  const int N = static_cast<int>(X.rows()), n = static_cast<int>(X.cols());
  const Hyper h = Unpack(theta, n, with_tool, configuration != nullptr);
  Eigen::MatrixXd Kse, K;
  ExactKernel(h, X, tools, configuration, &Kse, &K, U);
  Eigen::LLT<Eigen::MatrixXd> llt(K);
  if (llt.info() != Eigen::Success) return std::numeric_limits<double>::infinity();
  const Eigen::MatrixXd Kinv = llt.solve(Eigen::MatrixXd::Identity(N, N));
  const Eigen::MatrixXd A = Kinv * Y;
  // The groups: rows of one configuration (each row alone without a list).
  std::map<int, std::vector<int>> groups;
  for (int i = 0; i < N; ++i) groups[configuration ? (*configuration)[i] : i].push_back(i);
  double sum = 0;
  for (const auto& [id, rows] : groups) {
    const int b = static_cast<int>(rows.size());
    Eigen::MatrixXd Kgg(b, b), Ag(b, Y.cols());
    for (int u = 0; u < b; ++u) {
      for (int v = 0; v < b; ++v) Kgg(u, v) = Kinv(rows[u], rows[v]);
      Ag.row(u) = A.row(rows[u]);
    }
    sum += Kgg.ldlt().solve(Ag).squaredNorm();
  }
  return sum / N;
}

double GpValidationError(const Eigen::VectorXd& theta, bool with_tool, const Eigen::MatrixXd& X,
                         const std::vector<int>& tools, const Eigen::MatrixXd& Y,
                         const std::vector<int>* configuration, const Eigen::MatrixXd& Xv,
                         const std::vector<int>& validation_tools, const Eigen::MatrixXd& Yv,
                         const Eigen::MatrixXd* U, const Eigen::MatrixXd* Uv) {
  const int N = static_cast<int>(X.rows()), n = static_cast<int>(X.cols());
  const Hyper h = Unpack(theta, n, with_tool, configuration != nullptr);
  Eigen::MatrixXd Kse, K;
  ExactKernel(h, X, tools, configuration, &Kse, &K, U);
  Eigen::LLT<Eigen::MatrixXd> llt(K);
  if (llt.info() != Eigen::Success) return std::numeric_limits<double>::infinity();
  const Eigen::MatrixXd alpha = llt.solve(Y);
  const Eigen::VectorXd inv_l = h.l.cwiseInverse();
  double sum = 0;
  Eigen::RowVectorXd k(N);
  for (int v = 0; v < Xv.rows(); ++v) {
    for (int i = 0; i < N; ++i) {
      double d2 = 0;
      for (int j = 0; j < n; ++j) {
        const double d = (Xv(v, j) - X(i, j)) * inv_l(j);
        d2 += d * d;
      }
      k(i) = h.sf2 * std::exp(-0.5 * d2) * (validation_tools[v] == tools[i] ? 1.0 : h.rho);
      if (U != nullptr) k(i) *= Uv->row(v).dot(U->row(i));
    }
    sum += (Yv.row(v) - k * alpha).squaredNorm();
  }
  return Xv.rows() > 0 ? sum / Xv.rows() : 0.0;
}

}  // namespace internal

// ---- Fit.

std::vector<int> JointsBelowSpacing(const Eigen::VectorXd& length_scales,
                                    const Eigen::VectorXd& spacing) {
  std::vector<int> out;
  for (int j = 0; j < std::min(length_scales.size(), spacing.size()); ++j) {
    if (length_scales(j) < spacing(j)) out.push_back(j);
  }
  return out;
}

Eigen::VectorXd ResidualLayerSpacing(const std::vector<double>& q, int n,
                                     const Eigen::VectorXd& l) {
  Eigen::VectorXd spacing = Eigen::VectorXd::Zero(n);
  if (n < 1 || l.size() != n) return spacing;
  // The distinct configurations.
  std::map<std::vector<double>, int> seen;
  std::vector<const double*> configs;
  for (size_t r = 0; r + n <= q.size(); r += n) {
    if (seen.emplace(std::vector<double>(q.begin() + r, q.begin() + r + n), 0).second) {
      configs.push_back(q.data() + r);
    }
  }
  const int C = static_cast<int>(configs.size());
  if (C < 2) return spacing;
  std::vector<int> queries(C);
  std::iota(queries.begin(), queries.end(), 0);
  constexpr int kMaxQueries = 1000;
  if (C > kMaxQueries) {
    std::mt19937_64 rng(7);
    std::shuffle(queries.begin(), queries.end(), rng);
    queries.resize(kMaxQueries);
  }
  const Eigen::VectorXd inv_l = l.cwiseInverse();
  std::vector<std::vector<double>> gaps(n);
  for (int a : queries) {
    double best = std::numeric_limits<double>::infinity();
    int nearest = -1;
    for (int b = 0; b < C; ++b) {
      if (b == a) continue;
      const double d = ScaledSquaredDistance(configs[a], configs[b], inv_l.data(), n);
      if (d < best) {
        best = d;
        nearest = b;
      }
    }
    for (int j = 0; j < n; ++j) gaps[j].push_back(std::abs(configs[a][j] - configs[nearest][j]));
  }
  for (int j = 0; j < n; ++j) {
    std::vector<double>& g = gaps[j];
    std::nth_element(g.begin(), g.begin() + g.size() / 2, g.end());
    spacing(j) = g[g.size() / 2];
  }
  return spacing;
}

namespace {

// The rows of a fit: joint values (rows x n, row-major), tools, and what each row observes: Y
// (rows x 3, the residual) or, with U (rows x 3), Y (rows x 1) = u . m(q) + noise.
struct LayerRows {
  const double* Q = nullptr;
  const std::vector<int>* tools = nullptr;
  int rows = 0, n = 0;
  Eigen::MatrixXd Y;
  const Eigen::MatrixXd* U = nullptr;
  const double* q(int r) const { return Q + static_cast<size_t>(r) * n; }
};

// The configurations: rows with the same joint values (the tools measured at one stop).
struct LayerConfigurations {
  std::vector<int> of_row;
  std::vector<std::vector<int>> members;
  int count() const { return static_cast<int>(members.size()); }
};

LayerConfigurations GroupConfigurations(const LayerRows& d) {
  LayerConfigurations c;
  c.of_row.resize(d.rows);
  std::map<std::vector<double>, int> ids;
  for (int r = 0; r < d.rows; ++r) {
    const auto [it, added] = ids.emplace(std::vector<double>(d.q(r), d.q(r) + d.n),
                                         static_cast<int>(c.members.size()));
    if (added) c.members.emplace_back();
    c.of_row[r] = it->second;
    c.members[it->second].push_back(r);
  }
  return c;
}

// The hyperparameter rows and the validation rows as matrices (the tools, configurations and, for
// projected rows, directions of each).
struct FitSample {
  Eigen::MatrixXd X, Y, U, Xv, Yv, Uv;
  std::vector<int> tools, configuration, validation_tools;
  bool shared = false;     // some configuration has more than one row
  bool with_tool = false;  // the rows have more than one tool
  bool projected = false;
  int N() const { return static_cast<int>(X.rows()); }
  int V() const { return static_cast<int>(Xv.rows()); }
  const std::vector<int>* groups() const { return shared ? &configuration : nullptr; }
  const Eigen::MatrixXd* directions() const { return projected ? &U : nullptr; }
  const Eigen::MatrixXd* validation_directions() const { return projected ? &Uv : nullptr; }
};

// The hyperparameter rows: whole configurations, all of them or a seeded sample, so that the
// likelihood sees the rows of a configuration together (what they share is not a signal).
// The validation rows: the next configurations of the same order, as many rows at most, that
// choose between the candidates of the search when there are at least kMinValidation
// configurations.
FitSample SampleFitRows(const LayerRows& d, const LayerConfigurations& configs,
                        const ResidualLayerOptions& options) {
  constexpr int kMinValidation = 30;
  const int C = configs.count();
  const auto& members = configs.members;
  std::vector<int> sub, validation;
  int validation_configurations = 0;
  {
    std::vector<int> order(C);
    std::iota(order.begin(), order.end(), 0);
    if (d.rows > options.max_hyperparameter_rows) {
      std::mt19937_64 rng(options.seed);
      for (int i = 0; i + 1 < C; ++i) {
        std::uniform_int_distribution<int> pick(i, C - 1);
        std::swap(order[i], order[pick(rng)]);
      }
    }
    size_t next = 0;
    for (; next < order.size(); ++next) {
      const int c = order[next];
      if (!sub.empty() && static_cast<int>(sub.size() + members[c].size()) >
                              std::max(3, options.max_hyperparameter_rows)) {
        break;
      }
      sub.insert(sub.end(), members[c].begin(), members[c].end());
    }
    for (; next < order.size(); ++next) {
      const int c = order[next];
      if (static_cast<int>(validation.size() + members[c].size()) > static_cast<int>(sub.size())) {
        break;
      }
      validation.insert(validation.end(), members[c].begin(), members[c].end());
      ++validation_configurations;
    }
    std::sort(sub.begin(), sub.end());
    if (validation_configurations < kMinValidation) validation.clear();
  }
  const int n = d.n, outputs = static_cast<int>(d.Y.cols());
  const std::vector<int>& tools = *d.tools;
  FitSample s;
  s.projected = d.U != nullptr;
  const int N = static_cast<int>(sub.size());
  s.X.resize(N, n);
  s.Y.resize(N, outputs);
  if (s.projected) s.U.resize(N, 3);
  s.tools.resize(N);
  s.configuration.resize(N);
  for (int i = 0; i < N; ++i) {
    for (int j = 0; j < n; ++j) s.X(i, j) = d.q(sub[i])[j];
    s.Y.row(i) = d.Y.row(sub[i]);
    if (s.projected) s.U.row(i) = d.U->row(sub[i]);
    s.tools[i] = tools[sub[i]];
    s.configuration[i] = configs.of_row[sub[i]];
    s.shared = s.shared || (i > 0 && s.configuration[i] == s.configuration[i - 1]) ||
               members[configs.of_row[sub[i]]].size() > 1;
  }
  for (int i = 1; i < N; ++i) s.with_tool = s.with_tool || s.tools[i] != s.tools[0];
  const int V = static_cast<int>(validation.size());
  s.Xv.resize(V, n);
  s.Yv.resize(V, outputs);
  if (s.projected) s.Uv.resize(V, 3);
  s.validation_tools.resize(V);
  for (int i = 0; i < V; ++i) {
    for (int j = 0; j < n; ++j) s.Xv(i, j) = d.q(validation[i])[j];
    s.Yv.row(i) = d.Y.row(validation[i]);
    if (s.projected) s.Uv.row(i) = d.U->row(validation[i]);
    s.validation_tools[i] = tools[validation[i]];
  }
  return s;
}

struct HyperparameterSearch {
  Eigen::VectorXd theta;
  int iterations = 0;
  std::vector<double> start_loo;
  int chosen_start = 0;
};

// Bounds and weak log-normal priors (a factor e^2 wide): each length scale centred on the spread
// of its joint, the signal, the noise and the configuration's error on the residuals' spread. They
// decide only where the likelihood cannot (a joint that does not matter, a signal that cannot be
// told from noise); with hundreds of rows of real structure the likelihood outweighs them.
// Two starts: long length scales (three times each joint's spread: nearly linear over the data)
// and each joint's spread. The one whose exact GP predicts left-out configurations best is kept:
// the likelihood alone can prefer length scales so short that the layer reproduces its rows and
// predicts nothing between them. Then no signal (see below).
HyperparameterSearch SearchHyperparameters(const FitSample& s, int n,
                                           const ResidualLayerOptions& options) {
  const Eigen::MatrixXd& X = s.X;
  const Eigen::MatrixXd& Y = s.Y;
  const int N = s.N(), V = s.V();
  const bool with_tool = s.with_tool, shared = s.shared;
  const std::vector<int>* groups = s.groups();
  const Eigen::MatrixXd* U = s.directions();
  const int p = n + (with_tool ? 1 : 0) + 2 + (shared ? 1 : 0);
  Eigen::VectorXd lower(p), upper(p), centre(p);
  Eigen::VectorXd spread(n);
  for (int j = 0; j < n; ++j) {
    const double mean = X.col(j).mean();
    const double sd = std::sqrt((X.col(j).array() - mean).square().mean());
    spread(j) = sd > 1e-9 ? sd : 1e3;
    lower(j) = kLogLengthMin;
    upper(j) = kLogLengthMax;
    centre(j) = std::log(spread(j));
  }
  int k = n;
  const int tool_index = with_tool ? k++ : -1;
  if (with_tool) {
    lower(tool_index) = kLogToolMin;
    upper(tool_index) = kLogToolMax;
  }
  const int signal_index = k++, noise_index = k++, configuration_index = shared ? k : -1;
  const double y_sd = std::max(1e-5, std::sqrt(Y.array().square().mean()));
  for (int i : {signal_index, noise_index, configuration_index}) {
    if (i < 0) continue;
    lower(i) = kLogStdMin;
    upper(i) = kLogStdMax;
    centre(i) = std::log(y_sd);
  }
  constexpr double kPriorWidth = 2.0;
  auto prior = [&](int i) { return i != tool_index; };
  auto objective = [&](const Eigen::VectorXd& t, Eigen::VectorXd* g) {
    const double L =
        internal::GpLogMarginalLikelihood(t, with_tool, X, s.tools, Y, g, groups, U);
    if (!std::isfinite(L)) return std::numeric_limits<double>::infinity();
    double penalty = 0;
    *g *= -1.0 / N;
    for (int i = 0; i < p; ++i) {
      if (!prior(i)) continue;
      const double z = (t(i) - centre(i)) / kPriorWidth;
      penalty += 0.5 * z * z;
      (*g)(i) += z / kPriorWidth / N;
    }
    return (-L + penalty) / N;
  };
  // The held-out error of the exact GP at theta: on the validation rows (predicted from the
  // hyperparameter rows), else leave-one-configuration-out on the hyperparameter rows (which
  // favours what was fitted to them).
  auto held_out_error = [&](const Eigen::VectorXd& t) {
    if (V == 0) {
      return internal::GpLeaveOneConfigurationOut(t, with_tool, X, s.tools, Y, groups, U);
    }
    return internal::GpValidationError(t, with_tool, X, s.tools, Y, groups, s.Xv,
                                       s.validation_tools, s.Yv, U, s.validation_directions());
  };
  const double start_factor[2] = {3.0, 1.0};
  const double start_noise[2] = {0.5, 1.0 / 3};
  HyperparameterSearch out;
  double best_loo = std::numeric_limits<double>::infinity();
  for (int start = 0; start < 2; ++start) {
    Eigen::VectorXd t(p);
    for (int j = 0; j < n; ++j) t(j) = std::log(start_factor[start] * spread(j));
    if (with_tool) t(tool_index) = std::log(3.0);  // rho = 0.89
    t(signal_index) = std::log(y_sd);
    t(noise_index) = std::log(start_noise[start] * y_sd);
    if (shared) t(configuration_index) = std::log(start_noise[start] * y_sd);
    t = t.cwiseMax(lower).cwiseMin(upper);
    const int it = MinimizeBounded(objective, lower, upper, options.max_iterations, &t);
    const double loo = held_out_error(t);
    out.start_loo.push_back(std::sqrt(loo));
    if (start == 0 || loo < best_loo) {
      best_loo = loo;
      out.theta = t;
      out.iterations = it;
      out.chosen_start = start;
    }
  }
  // And no signal at all: the chosen optimum with its signal variance moved to the noise. When it
  // predicts the left-out configurations at least as well, the rows hold nothing a layer can
  // predict (the likelihood of hundreds of rows of noise can still prefer a small signal of short
  // length scales: ten hyperparameters fitted to noise), and the layer is that of no signal.
  {
    const Eigen::VectorXd& theta = out.theta;
    Eigen::VectorXd t = theta;
    t(noise_index) = 0.5 * std::log(std::exp(2 * theta(noise_index)) +
                                    std::exp(2 * theta(signal_index)));
    t(signal_index) = kLogStdMin;
    const double loo = held_out_error(t);
    out.start_loo.push_back(std::sqrt(loo));
    if (loo <= best_loo) {
      out.theta = t;
      out.iterations = 0;
      out.chosen_start = 2;
    }
  }
  return out;
}

// Inducing inputs: farthest-point sampling in length-scale units (the tool's one-hot distance
// -2 log rho between different tools), from row 0, until every row is within
// options.inducing_radius of one or there are options.max_inducing. *far: the largest squared
// distance of a row to its nearest inducing input.
std::vector<int> ChooseInducing(const LayerRows& d, const Hyper& h, bool with_tool,
                                const ResidualLayerOptions& options, double* far_out) {
  const int rows = d.rows, n = d.n;
  const std::vector<int>& tools = *d.tools;
  const Eigen::VectorXd inv_l = h.l.cwiseInverse();
  const double tool_d2 = with_tool ? 2.0 / (h.lt * h.lt) : 0.0;
  const double radius2 = options.inducing_radius * options.inducing_radius;
  std::vector<double> nearest(rows, std::numeric_limits<double>::infinity());
  std::vector<int> chosen;
  int next = 0;
  double far = 0;
  const int max_m = std::max(1, std::min(options.max_inducing, rows));
  while (static_cast<int>(chosen.size()) < max_m) {
    chosen.push_back(next);
    const double* z = d.q(next);
    const int zt = tools[next];
    far = -1;
    int far_row = -1;
    for (int r = 0; r < rows; ++r) {
      double dist = ScaledSquaredDistance(d.q(r), z, inv_l.data(), n);
      if (tools[r] != zt) dist += tool_d2;
      nearest[r] = std::min(nearest[r], dist);
      if (nearest[r] > far) {
        far = nearest[r];
        far_row = r;
      }
    }
    // Every row is (numerically) an inducing input already, or near enough to one.
    if (!(far > 1e-12) || far <= radius2) break;
    next = far_row;
  }
  *far_out = far;
  return chosen;
}

// K_mm of the layer's inducing inputs (with its jitter) and its Cholesky factor's L.
Status InducingFactor(const ResidualLayer& out, const Hyper& h, Eigen::MatrixXd* Lm) {
  const int m = out.num_inducing();
  Eigen::MatrixXd Kmm(m, m);
  {
    Eigen::VectorXd k_col;
    for (int a = 0; a < m; ++a) {
      out.KernelVector(out.inducing_q.row(a).eval().data(), out.inducing_tool[a], &k_col);
      Kmm.col(a) = k_col;
    }
  }
  Kmm = 0.5 * (Kmm + Kmm.transpose());
  Kmm.diagonal().array() += kInducingJitter * h.sf2;
  Eigen::LLT<Eigen::MatrixXd> lm(Kmm);
  if (lm.info() != Eigen::Success) {
    return Status::Error("the residual layer's inducing kernel matrix is not positive definite");
  }
  *Lm = lm.matrixL();
  return Status::Ok();
}

// W = Lm^-T (I - Binv) Lm^-1 into out->variance.
void StoreVariance(const Eigen::MatrixXd& Lm, const Eigen::MatrixXd& Binv, ResidualLayer* out) {
  const int m = static_cast<int>(Lm.rows());
  Eigen::MatrixXd inner = Eigen::MatrixXd::Identity(m, m) - Binv;
  Eigen::MatrixXd T = Lm.transpose().triangularView<Eigen::Upper>().solve(inner);
  out->variance =
      Lm.transpose().triangularView<Eigen::Upper>().solve(T.transpose()).transpose();
  out->variance = 0.5 * (out->variance + out->variance.transpose());
}

// The DTC posterior of residual rows (3 outputs) with the noise of the rows, Lambda: s_n^2 I plus
// s_c^2 between the rows of a configuration (block g: Lambda_g^-1 = s_n^-2 (I - gamma_g 1 1^T),
// gamma_g = s_c^2 / (s_n^2 + b_g s_c^2)). Lm = chol(K_mm), V = Lm^-1 K_mn,
// B = I + V Lambda^-1 V^T, alpha = Lm^-T B^-1 V Lambda^-1 Y.
Status ResidualPosterior(const LayerRows& d, const LayerConfigurations& configs, const Hyper& h,
                         ResidualLayer* out) {
  const int m = out->num_inducing();
  const std::vector<int>& tools = *d.tools;
  const auto& members = configs.members;
  Eigen::MatrixXd Lm;
  if (Status s = InducingFactor(*out, h, &Lm); !s.ok()) return s;
  // Fixed chunks of configurations (the result does not depend on the number of threads).
  const RowChunks chunks = PartitionRows(configs.count(), 512, 64);
  std::vector<Eigen::MatrixXd> VVt(chunks.chunks), VY(chunks.chunks);
  ForEachTask(chunks.chunks, ThreadsFor(chunks.chunks), [&](int c, int /*thread*/) {
    int count = 0;
    for (int g = chunks.begin(c); g < chunks.end(c); ++g) count += members[g].size();
    Eigen::MatrixXd Kmn(m, count), Yc(count, 3);
    Eigen::VectorXd k_col;
    int col = 0;
    for (int g = chunks.begin(c); g < chunks.end(c); ++g) {
      for (int r : members[g]) {
        out->KernelVector(d.q(r), tools[r], &k_col);
        Kmn.col(col) = k_col;
        Yc.row(col++) = d.Y.row(r);
      }
    }
    Lm.triangularView<Eigen::Lower>().solveInPlace(Kmn);  // V
    VVt[c] = Eigen::MatrixXd::Zero(m, m);
    VVt[c].selfadjointView<Eigen::Lower>().rankUpdate(Kmn);
    VY[c] = Kmn * Yc;
    if (h.sc2 > 0) {
      col = 0;
      for (int g = chunks.begin(c); g < chunks.end(c); ++g) {
        const int b = static_cast<int>(members[g].size());
        if (b > 1) {
          const double gamma = h.sc2 / (h.sn2 + b * h.sc2);
          const Eigen::VectorXd sv = Kmn.middleCols(col, b).rowwise().sum();
          const Eigen::RowVector3d sy = Yc.middleRows(col, b).colwise().sum();
          VVt[c].selfadjointView<Eigen::Lower>().rankUpdate(sv, -gamma);
          VY[c].noalias() -= gamma * sv * sy;
        }
        col += b;
      }
    }
  });
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(m, m), VYs = Eigen::MatrixXd::Zero(m, 3);
  for (int c = 0; c < chunks.chunks; ++c) {
    B += VVt[c];
    VYs += VY[c];
  }
  B = B.selfadjointView<Eigen::Lower>();
  const double beta = 1.0 / h.sn2;
  B *= beta;
  B.diagonal().array() += 1.0;
  Eigen::LLT<Eigen::MatrixXd> lb(B);
  if (lb.info() != Eigen::Success) {
    return Status::Error("the residual layer's posterior matrix is not positive definite");
  }
  const Eigen::MatrixXd Binv = lb.solve(Eigen::MatrixXd::Identity(m, m));
  out->weights = beta * Lm.transpose().triangularView<Eigen::Upper>().solve(Binv * VYs);
  StoreVariance(Lm, Binv, out);
  return Status::Ok();
}

// The DTC posterior of projected rows y_r = u_r . m(q_r) + noise. The inducing variables are the
// three components of m at each inducing input, whitened: m(z) = (Lm (x) I3) v, v ~ N(0, I_3m).
// Row r's design row is kron(V_r, u_r) (V = Lm^-1 K_mn), so, with v's entries ordered component
// first (c m + i) and Vc = V diag(U_c):
//   B_cd = delta_cd I + Vc Lambda^-1 Vd^T,   v = B^-1 [Vc Lambda^-1 y]_c,
//   alpha (m x 3, column c) = Lm^-T v_c,
// Lambda = s_n^2 I plus s_c^2 u_a . u_b between the rows of a configuration. A component no row's
// direction has is neither in the right-hand side nor coupled to one that is: its weights are 0.
// The stored W is the average over the three components of the component's own
// Lm^-T (I - (B^-1)_cc) Lm^-1: Std is then the RMS over the axes of the components' deviations.
Status ProjectedPosterior(const LayerRows& d, const LayerConfigurations& configs, const Hyper& h,
                          ResidualLayer* out) {
  const int m = out->num_inducing(), rows = d.rows;
  const std::vector<int>& tools = *d.tools;
  const Eigen::MatrixXd& U = *d.U;
  Eigen::MatrixXd Lm;
  if (Status s = InducingFactor(*out, h, &Lm); !s.ok()) return s;
  Eigen::MatrixXd Vt(rows, m);  // V^T
  {
    Eigen::MatrixXd Kmn(m, rows);
    Eigen::VectorXd k_col;
    for (int r = 0; r < rows; ++r) {
      out->KernelVector(d.q(r), tools[r], &k_col);
      Kmn.col(r) = k_col;
    }
    Lm.triangularView<Eigen::Lower>().solveInPlace(Kmn);
    Vt = Kmn.transpose();
  }
  // Lambda^-1 applied to the columns of a rows x k matrix, configuration by configuration.
  std::vector<Eigen::LLT<Eigen::MatrixXd>> blocks(configs.count());
  for (int g = 0; g < configs.count(); ++g) {
    const std::vector<int>& rs = configs.members[g];
    const int b = static_cast<int>(rs.size());
    Eigen::MatrixXd Lg = Eigen::MatrixXd::Zero(b, b);
    for (int a = 0; a < b; ++a) {
      for (int c = 0; c < b; ++c) Lg(a, c) = h.sc2 * U.row(rs[a]).dot(U.row(rs[c]));
      Lg(a, a) += h.sn2;
    }
    blocks[g].compute(Lg);
  }
  auto apply_inverse_noise = [&](const Eigen::MatrixXd& A) {
    Eigen::MatrixXd out_a(A.rows(), A.cols());
    for (int g = 0; g < configs.count(); ++g) {
      const std::vector<int>& rs = configs.members[g];
      const int b = static_cast<int>(rs.size());
      Eigen::MatrixXd Ag(b, A.cols());
      for (int a = 0; a < b; ++a) Ag.row(a) = A.row(rs[a]);
      Ag = blocks[g].solve(Ag);
      for (int a = 0; a < b; ++a) out_a.row(rs[a]) = Ag.row(a);
    }
    return out_a;
  };
  Eigen::MatrixXd B = Eigen::MatrixXd::Identity(3 * m, 3 * m);
  Eigen::VectorXd rhs(3 * m);
  const Eigen::VectorXd y = d.Y.col(0);
  const Eigen::VectorXd Ly = apply_inverse_noise(y);
  for (int dd = 0; dd < 3; ++dd) {
    const Eigen::MatrixXd Vd = U.col(dd).asDiagonal() * Vt;  // rows x m
    const Eigen::MatrixXd LVd = apply_inverse_noise(Vd);
    rhs.segment(dd * m, m) = Vd.transpose() * Ly;
    for (int c = 0; c <= dd; ++c) {
      const Eigen::MatrixXd Vc = U.col(c).asDiagonal() * Vt;
      const Eigen::MatrixXd Bcd = Vc.transpose() * LVd;
      B.block(c * m, dd * m, m, m) += Bcd;
      if (c != dd) B.block(dd * m, c * m, m, m) += Bcd.transpose();
    }
  }
  B = 0.5 * (B + B.transpose());
  Eigen::LLT<Eigen::MatrixXd> lb(B);
  if (lb.info() != Eigen::Success) {
    return Status::Error("the residual layer's posterior matrix is not positive definite");
  }
  const Eigen::VectorXd v = lb.solve(rhs);
  out->weights.resize(m, 3);
  for (int c = 0; c < 3; ++c) {
    out->weights.col(c) =
        Lm.transpose().triangularView<Eigen::Upper>().solve(v.segment(c * m, m));
  }
  Eigen::MatrixXd Binv_mean = Eigen::MatrixXd::Zero(m, m);
  for (int c = 0; c < 3; ++c) {
    Eigen::MatrixXd E = Eigen::MatrixXd::Zero(3 * m, m);
    E.middleRows(c * m, m).setIdentity();
    Binv_mean += lb.solve(E).middleRows(c * m, m);
  }
  StoreVariance(Lm, Binv_mean / 3.0, out);
  return Status::Ok();
}

// The rows' checks shared by both fits.
Status CheckLayerRows(const LayerRows& d, int num_tools) {
  if (d.n < 1 || num_tools < 1) return Status::Error("the residual layer needs joints and tools");
  if (d.rows < 3) return Status::Error("the residual layer needs at least 3 rows");
  for (int r = 0; r < d.rows; ++r) {
    const int tool = (*d.tools)[r];
    if (tool < 0 || tool >= num_tools) {
      return Status::Error("row " + std::to_string(r + 1) + ": tool index out of range");
    }
    if (!d.Y.row(r).allFinite() || (d.U != nullptr && !d.U->row(r).allFinite())) {
      return Status::Error("row " + std::to_string(r + 1) + ": the residual is not finite");
    }
    for (int j = 0; j < d.n; ++j) {
      if (!std::isfinite(d.q(r)[j])) {
        return Status::Error("row " + std::to_string(r + 1) + ": a joint value is not finite");
      }
    }
  }
  return Status::Ok();
}

// The fit on checked rows (FitResidualLayer, FitResidualLayerProjected).
Status FitLayerRows(const LayerRows& d, const std::vector<double>& q, int num_tools,
                    const ResidualLayerOptions& options, ResidualLayer* layer,
                    ResidualLayerFit* fit) {
  const int rows = d.rows, n = d.n;
  const std::vector<int>& tools = *d.tools;
  const LayerConfigurations configs = GroupConfigurations(d);
  const FitSample sample = SampleFitRows(d, configs, options);
  const HyperparameterSearch search = SearchHyperparameters(sample, n, options);
  const Eigen::VectorXd& theta = search.theta;
  const Hyper h = Unpack(theta, n, sample.with_tool, sample.shared);

  ResidualLayer out;
  out.num_joints = n;
  out.num_tools = num_tools;
  out.length_scales = h.l;
  out.tool_correlation = h.rho;
  out.signal_std = std::sqrt(h.sf2);
  out.noise_std = std::sqrt(h.sn2);
  out.fitted_rows = rows;
  double far = 0;
  const std::vector<int> chosen = ChooseInducing(d, h, sample.with_tool, options, &far);
  const int m = static_cast<int>(chosen.size());
  out.inducing_q.resize(m, n);
  out.inducing_tool.resize(m);
  for (int i = 0; i < m; ++i) {
    for (int j = 0; j < n; ++j) out.inducing_q(i, j) = d.q(chosen[i])[j];
    out.inducing_tool[i] = tools[chosen[i]];
  }
  out.weights = Eigen::MatrixXd::Zero(m, 3);
  out.variance = Eigen::MatrixXd::Zero(m, m);
  const Status posterior = d.U == nullptr ? ResidualPosterior(d, configs, h, &out)
                                          : ProjectedPosterior(d, configs, h, &out);
  if (!posterior.ok()) return posterior;
  if (!out.weights.allFinite() || !out.variance.allFinite()) {
    return Status::Error("the residual layer's posterior is not finite");
  }
  if (fit != nullptr) {
    fit->hyperparameter_rows = sample.N();
    fit->iterations = search.iterations;
    fit->log_marginal_likelihood = internal::GpLogMarginalLikelihood(
        theta, sample.with_tool, sample.X, sample.tools, sample.Y, nullptr, sample.groups(),
        sample.directions());
    fit->start_loo_rms = search.start_loo;
    fit->chosen_start = search.chosen_start;
    fit->configuration_std = std::sqrt(h.sc2);
    fit->configurations = configs.count();
    fit->validation_rows = sample.V();
    fit->spacing = ResidualLayerSpacing(q, n, h.l);
    fit->inducing_coverage = std::sqrt(std::max(0.0, far));
    double before = 0, after = 0;
    for (int r = 0; r < rows; ++r) {
      const Eigen::Vector3d mean = out.Mean(d.q(r), tools[r]);
      if (d.U == nullptr) {
        const Eigen::Vector3d e = d.Y.row(r).transpose();
        before += e.squaredNorm();
        after += (e - mean).squaredNorm();
      } else {
        const double y = d.Y(r, 0);
        before += y * y;
        after += std::pow(y - d.U->row(r).dot(mean), 2);
      }
    }
    fit->residual_rms_before = std::sqrt(before / rows);
    fit->residual_rms_after = std::sqrt(after / rows);
  }
  *layer = std::move(out);
  return Status::Ok();
}

}  // namespace

Status FitResidualLayer(const std::vector<double>& q, const std::vector<int>& tools,
                        const std::vector<Eigen::Vector3d>& residuals, int num_joints,
                        int num_tools, const ResidualLayerOptions& options, ResidualLayer* layer,
                        ResidualLayerFit* fit) {
  const int rows = static_cast<int>(residuals.size());
  if (num_joints < 1 || num_tools < 1) {
    return Status::Error("the residual layer needs joints and tools");
  }
  if (static_cast<int>(tools.size()) != rows ||
      q.size() != static_cast<size_t>(rows) * num_joints) {
    return Status::Error("the residual layer's rows, tools and joint values differ in number");
  }
  LayerRows d;
  d.Q = q.data();
  d.tools = &tools;
  d.rows = rows;
  d.n = num_joints;
  d.Y.resize(rows, 3);
  for (int r = 0; r < rows; ++r) d.Y.row(r) = residuals[r].transpose();
  if (Status s = CheckLayerRows(d, num_tools); !s.ok()) return s;
  return FitLayerRows(d, q, num_tools, options, layer, fit);
}

Status FitResidualLayerProjected(const std::vector<double>& q, const std::vector<int>& tools,
                                 const std::vector<Eigen::Vector3d>& directions,
                                 const std::vector<double>& values, int num_joints,
                                 int num_tools, const ResidualLayerOptions& options,
                                 ResidualLayer* layer, ResidualLayerFit* fit) {
  const int rows = static_cast<int>(values.size());
  if (num_joints < 1 || num_tools < 1) {
    return Status::Error("the residual layer needs joints and tools");
  }
  if (static_cast<int>(tools.size()) != rows || static_cast<int>(directions.size()) != rows ||
      q.size() != static_cast<size_t>(rows) * num_joints) {
    return Status::Error(
        "the residual layer's rows, tools, directions and joint values differ in number");
  }
  LayerRows d;
  d.Q = q.data();
  d.tools = &tools;
  d.rows = rows;
  d.n = num_joints;
  d.Y.resize(rows, 1);
  Eigen::MatrixXd U(rows, 3);
  for (int r = 0; r < rows; ++r) {
    d.Y(r, 0) = values[r];
    U.row(r) = directions[r].transpose();
  }
  d.U = &U;
  if (Status s = CheckLayerRows(d, num_tools); !s.ok()) return s;
  for (int r = 0; r < rows; ++r) {
    if (!(U.row(r).norm() > 0)) {
      return Status::Error("row " + std::to_string(r + 1) + ": the direction is zero");
    }
  }
  return FitLayerRows(d, q, num_tools, options, layer, fit);
}

}  // namespace lpoe
