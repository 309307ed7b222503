// The learned residual layer: kernel, prediction, hyperparameters by the marginal likelihood and
// the sparse posterior (lpoe/residual_layer.h, docs/residual_layer.md).
#include "lpoe/residual_layer.h"

#include <algorithm>
#include <cmath>
#include <deque>
#include <limits>
#include <numeric>
#include <random>
#include <sstream>
#include <utility>

#include <Eigen/Cholesky>
#include <Eigen/Dense>

#include "lpoe/kernels.h"
#include "lpoe/parallel.h"

namespace lpoe {
namespace {

constexpr double kTwoPi = 6.283185307179586476925286766559;
// Added to the diagonal of the exact kernel matrix (relative to s_f^2) and of K_mm.
constexpr double kExactJitter = 1e-8;
constexpr double kInducingJitter = 1e-6;

// Bounds of the hyperparameters (log space): length scales 1e-3..1e6 (rad or mm), the tool's
// 0.1..10 (rho from e^-100 to 0.99), s_f and s_n 1e-6..1e3 mm.
constexpr double kLogLengthMin = -6.907755278982137, kLogLengthMax = 13.815510557964274;
constexpr double kLogToolMin = -2.302585092994046, kLogToolMax = 2.302585092994046;
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
};

Hyper Unpack(const Eigen::VectorXd& theta, int n, bool with_tool) {
  Hyper h;
  h.l = theta.head(n).array().exp();
  int k = n;
  if (with_tool) {
    h.lt = std::exp(theta(k++));
    h.rho = std::exp(-1.0 / (h.lt * h.lt));
  }
  h.sf2 = std::exp(2 * theta(k++));
  h.sn2 = std::exp(2 * theta(k));
  return h;
}

// Small L-BFGS with projection on box bounds and backtracking (Armijo) line search; minimizes f.
template <typename F>
int MinimizeLbfgs(const F& f, const Eigen::VectorXd& lower, const Eigen::VectorXd& upper,
                  int max_iterations, Eigen::VectorXd* x) {
  constexpr int kHistory = 7;
  constexpr double kMaxStep = 2.0;  // per coordinate, log space
  Eigen::VectorXd g, g_new, x_new;
  double fx = f(*x, &g);
  if (!std::isfinite(fx)) return 0;
  std::deque<std::pair<Eigen::VectorXd, Eigen::VectorXd>> history;  // (s, y)
  int it = 0;
  for (; it < max_iterations; ++it) {
    // Two-loop recursion.
    Eigen::VectorXd d = -g;
    std::vector<double> a(history.size());
    for (int i = static_cast<int>(history.size()) - 1; i >= 0; --i) {
      const auto& [s, y] = history[i];
      a[i] = s.dot(d) / y.dot(s);
      d -= a[i] * y;
    }
    if (!history.empty()) {
      const auto& [s, y] = history.back();
      d *= s.dot(y) / y.dot(y);
    }
    for (size_t i = 0; i < history.size(); ++i) {
      const auto& [s, y] = history[i];
      const double b = y.dot(d) / y.dot(s);
      d += (a[i] - b) * s;
    }
    if (!(g.dot(d) < 0)) {
      history.clear();
      d = -g;
    }
    const double largest = d.cwiseAbs().maxCoeff();
    if (!(largest > 0)) break;
    double t = std::min(1.0, kMaxStep / largest);
    if (history.empty()) t = std::min(t, 1.0 / std::max(1.0, g.norm()));
    bool accepted = false;
    double f_new = 0;
    for (int ls = 0; ls < 40; ++ls) {
      x_new = (*x + t * d).cwiseMax(lower).cwiseMin(upper);
      f_new = f(x_new, &g_new);
      if (std::isfinite(f_new) && f_new <= fx + 1e-4 * g.dot(x_new - *x)) {
        accepted = true;
        break;
      }
      t *= 0.5;
    }
    if (!accepted) break;
    Eigen::VectorXd s = x_new - *x, y = g_new - g;
    const double change = fx - f_new;
    *x = x_new;
    g = g_new;
    fx = f_new;
    if (s.dot(y) > 1e-12 * s.norm() * y.norm()) {
      history.emplace_back(std::move(s), std::move(y));
      if (static_cast<int>(history.size()) > kHistory) history.pop_front();
    }
    // Projected gradient: components pushing against an active bound do not count.
    double pg = 0;
    for (int i = 0; i < x->size(); ++i) {
      const bool at_lower = (*x)(i) <= lower(i) && g(i) > 0;
      const bool at_upper = (*x)(i) >= upper(i) && g(i) < 0;
      if (!at_lower && !at_upper) pg = std::max(pg, std::abs(g(i)));
    }
    if (pg < 1e-7 || change < 1e-12 * (1 + std::abs(fx))) {
      ++it;
      break;
    }
  }
  return it;
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
                               const Eigen::MatrixXd& Y, Eigen::VectorXd* gradient) {
  const int N = static_cast<int>(X.rows()), n = static_cast<int>(X.cols());
  const Hyper h = Unpack(theta, n, with_tool);
  const Eigen::VectorXd inv_l = h.l.cwiseInverse();
  const Eigen::MatrixXd Xs = X * inv_l.asDiagonal();  // scaled inputs
  Eigen::MatrixXd Kse(N, N);
  for (int b = 0; b < N; ++b) {
    for (int a = b; a < N; ++a) {
      double d2 = (Xs.row(a) - Xs.row(b)).squaredNorm();
      double k = h.sf2 * std::exp(-0.5 * d2);
      if (tools[a] != tools[b]) k *= h.rho;
      Kse(a, b) = Kse(b, a) = k;
    }
  }
  const double diag = h.sn2 + kExactJitter * h.sf2;
  Eigen::MatrixXd K = Kse;
  K.diagonal().array() += diag;
  Eigen::LLT<Eigen::MatrixXd> llt(K);
  if (llt.info() != Eigen::Success) return -std::numeric_limits<double>::infinity();
  const Eigen::MatrixXd A = llt.solve(Y);  // N x 3
  const int outputs = static_cast<int>(Y.cols());
  double log_det = 0;
  for (int i = 0; i < N; ++i) log_det += 2 * std::log(llt.matrixL()(i, i));
  const double L = -0.5 * (Y.array() * A.array()).sum() - 0.5 * outputs * log_det -
                   0.5 * outputs * N * std::log(kTwoPi);
  if (gradient == nullptr) return L;
  // dL/dtheta = 1/2 tr(M dK/dtheta), M = A A^T - outputs K^-1.
  Eigen::MatrixXd M = A * A.transpose();
  M.noalias() -= outputs * llt.solve(Eigen::MatrixXd::Identity(N, N));
  const int p = static_cast<int>(theta.size());
  gradient->setZero(p);
  Eigen::MatrixXd MK = M.cwiseProduct(Kse);
  for (int j = 0; j < n; ++j) {
    double s = 0;
    for (int b = 0; b < N; ++b) {
      for (int a = 0; a < N; ++a) {
        const double d = Xs(a, j) - Xs(b, j);
        s += MK(a, b) * d * d;
      }
    }
    (*gradient)(j) = 0.5 * s;  // dK/dlog l_j = K .* d^2 / l^2
  }
  int k = n;
  if (with_tool) {
    double s = 0;
    for (int b = 0; b < N; ++b) {
      for (int a = 0; a < N; ++a) {
        if (tools[a] != tools[b]) s += MK(a, b);
      }
    }
    (*gradient)(k++) = 0.5 * s * 2.0 / (h.lt * h.lt);  // d rho/d log l_t = rho 2 / l_t^2
  }
  const double trace_M = M.trace();
  (*gradient)(k++) = 0.5 * (2 * MK.sum() + trace_M * 2 * kExactJitter * h.sf2);
  (*gradient)(k) = 0.5 * trace_M * 2 * h.sn2;
  return L;
}

}  // namespace internal

// ---- Fit.

Status FitResidualLayer(const std::vector<double>& q, const std::vector<int>& tools,
                        const std::vector<Eigen::Vector3d>& residuals, int num_joints,
                        int num_tools, const ResidualLayerOptions& options, ResidualLayer* layer,
                        ResidualLayerFit* fit) {
  const int rows = static_cast<int>(residuals.size());
  const int n = num_joints;
  if (n < 1 || num_tools < 1) return Status::Error("the residual layer needs joints and tools");
  if (static_cast<int>(tools.size()) != rows || q.size() != static_cast<size_t>(rows) * n) {
    return Status::Error("the residual layer's rows, tools and joint values differ in number");
  }
  if (rows < 3) return Status::Error("the residual layer needs at least 3 rows");
  for (int r = 0; r < rows; ++r) {
    if (tools[r] < 0 || tools[r] >= num_tools) {
      return Status::Error("row " + std::to_string(r + 1) + ": tool index out of range");
    }
    if (!residuals[r].allFinite()) {
      return Status::Error("row " + std::to_string(r + 1) + ": the residual is not finite");
    }
    for (int j = 0; j < n; ++j) {
      if (!std::isfinite(q[static_cast<size_t>(r) * n + j])) {
        return Status::Error("row " + std::to_string(r + 1) + ": a joint value is not finite");
      }
    }
  }
  const double* Q = q.data();
  auto qrow = [&](int r) { return Q + static_cast<size_t>(r) * n; };

  // The hyperparameter rows: all, or a seeded subsample.
  std::vector<int> sub(rows);
  std::iota(sub.begin(), sub.end(), 0);
  if (rows > options.max_hyperparameter_rows) {
    std::mt19937_64 rng(options.seed);
    for (int i = 0; i < options.max_hyperparameter_rows; ++i) {
      std::uniform_int_distribution<int> pick(i, rows - 1);
      std::swap(sub[i], sub[pick(rng)]);
    }
    sub.resize(options.max_hyperparameter_rows);
    std::sort(sub.begin(), sub.end());
  }
  const int N = static_cast<int>(sub.size());
  Eigen::MatrixXd X(N, n), Y(N, 3);
  std::vector<int> sub_tools(N);
  for (int i = 0; i < N; ++i) {
    for (int j = 0; j < n; ++j) X(i, j) = qrow(sub[i])[j];
    Y.row(i) = residuals[sub[i]].transpose();
    sub_tools[i] = tools[sub[i]];
  }
  bool with_tool = false;
  for (int i = 1; i < N; ++i) with_tool = with_tool || sub_tools[i] != sub_tools[0];

  // Start: length scales the spread of each joint, s_f the residuals' spread, s_n a third of it.
  const int p = n + (with_tool ? 1 : 0) + 2;
  Eigen::VectorXd theta(p), lower(p), upper(p);
  for (int j = 0; j < n; ++j) {
    const double mean = X.col(j).mean();
    const double sd = std::sqrt((X.col(j).array() - mean).square().mean());
    theta(j) = std::log(sd > 1e-9 ? sd : 1e3);
    lower(j) = kLogLengthMin;
    upper(j) = kLogLengthMax;
  }
  int k = n;
  if (with_tool) {
    theta(k) = 0;
    lower(k) = kLogToolMin;
    upper(k++) = kLogToolMax;
  }
  const double y_sd = std::max(1e-5, std::sqrt(Y.array().square().mean()));
  theta(k) = std::log(y_sd);
  lower(k) = kLogStdMin;
  upper(k++) = kLogStdMax;
  theta(k) = std::log(y_sd / 3);
  lower(k) = kLogStdMin;
  upper(k) = kLogStdMax;
  theta = theta.cwiseMax(lower).cwiseMin(upper);

  // A weak log-normal prior on the noise (centred on the residuals' spread, a factor
  // e^2 wide): where the likelihood cannot tell signal from noise (inputs so far apart in
  // length-scale units that the kernel matrix is diagonal: "signal" uncorrelated between rows is
  // noise) it keeps the noise, instead of a layer that interpolates the noise of its rows. With
  // real structure the likelihood of hundreds of rows outweighs it.
  const int noise_index = p - 1;
  const double noise_centre = std::log(y_sd), noise_width = 2.0;
  auto objective = [&](const Eigen::VectorXd& t, Eigen::VectorXd* g) {
    const double L = internal::GpLogMarginalLikelihood(t, with_tool, X, sub_tools, Y, g);
    if (!std::isfinite(L)) return std::numeric_limits<double>::infinity();
    const double z = (t(noise_index) - noise_centre) / noise_width;
    *g *= -1.0 / N;
    (*g)(noise_index) += z / noise_width / N;
    return (-L + 0.5 * z * z) / N;
  };
  const int iterations = MinimizeLbfgs(objective, lower, upper, options.max_iterations, &theta);
  const Hyper h = Unpack(theta, n, with_tool);

  ResidualLayer out;
  out.num_joints = n;
  out.num_tools = num_tools;
  out.length_scales = h.l;
  out.tool_correlation = h.rho;
  out.signal_std = std::sqrt(h.sf2);
  out.noise_std = std::sqrt(h.sn2);
  out.fitted_rows = rows;

  // Inducing inputs: farthest-point sampling in length-scale units (the tool's one-hot distance
  // -2 log rho between different tools), from row 0.
  const Eigen::VectorXd inv_l = h.l.cwiseInverse();
  const double tool_d2 = with_tool ? 2.0 / (h.lt * h.lt) : 0.0;
  std::vector<double> nearest(rows, std::numeric_limits<double>::infinity());
  std::vector<int> chosen;
  int next = 0;
  const int max_m = std::max(1, std::min(options.max_inducing, rows));
  while (static_cast<int>(chosen.size()) < max_m) {
    chosen.push_back(next);
    const double* z = qrow(next);
    const int zt = tools[next];
    double far = -1;
    int far_row = -1;
    for (int r = 0; r < rows; ++r) {
      double d = ScaledSquaredDistance(qrow(r), z, inv_l.data(), n);
      if (tools[r] != zt) d += tool_d2;
      nearest[r] = std::min(nearest[r], d);
      if (nearest[r] > far) {
        far = nearest[r];
        far_row = r;
      }
    }
    if (!(far > 1e-12)) break;  // every row is (numerically) an inducing input already
    next = far_row;
  }
  const int m = static_cast<int>(chosen.size());
  out.inducing_q.resize(m, n);
  out.inducing_tool.resize(m);
  for (int i = 0; i < m; ++i) {
    for (int j = 0; j < n; ++j) out.inducing_q(i, j) = qrow(chosen[i])[j];
    out.inducing_tool[i] = tools[chosen[i]];
  }

  // The DTC posterior: Lm = chol(K_mm), V = Lm^-1 K_mn, B = I + V V^T / s_n^2.
  out.weights = Eigen::MatrixXd::Zero(m, 3);
  out.variance = Eigen::MatrixXd::Zero(m, m);
  Eigen::MatrixXd Kmm(m, m);
  {
    Eigen::VectorXd k_col;
    for (int a = 0; a < m; ++a) {
      out.KernelVector(qrow(chosen[a]), out.inducing_tool[a], &k_col);
      Kmm.col(a) = k_col;
    }
  }
  Kmm = 0.5 * (Kmm + Kmm.transpose());
  Kmm.diagonal().array() += kInducingJitter * h.sf2;
  Eigen::LLT<Eigen::MatrixXd> lm(Kmm);
  if (lm.info() != Eigen::Success) {
    return Status::Error("the residual layer's inducing kernel matrix is not positive definite");
  }
  const Eigen::MatrixXd Lm = lm.matrixL();
  const RowChunks chunks = PartitionRows(rows, 2048, 64);
  std::vector<Eigen::MatrixXd> VVt(chunks.chunks), VY(chunks.chunks);
  ForEachTask(chunks.chunks, ThreadsFor(chunks.chunks), [&](int c, int /*thread*/) {
    const int begin = chunks.begin(c), end = chunks.end(c);
    Eigen::MatrixXd Kmn(m, end - begin), Yc(end - begin, 3);
    Eigen::VectorXd k_col;
    for (int r = begin; r < end; ++r) {
      out.KernelVector(qrow(r), tools[r], &k_col);
      Kmn.col(r - begin) = k_col;
      Yc.row(r - begin) = residuals[r].transpose();
    }
    Lm.triangularView<Eigen::Lower>().solveInPlace(Kmn);  // V
    VVt[c] = Eigen::MatrixXd::Zero(m, m);
    VVt[c].selfadjointView<Eigen::Lower>().rankUpdate(Kmn);
    VY[c] = Kmn * Yc;
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
  out.weights = beta * Lm.transpose().triangularView<Eigen::Upper>().solve(Binv * VYs);
  Eigen::MatrixXd inner = Eigen::MatrixXd::Identity(m, m) - Binv;
  // W = Lm^-T (I - B^-1) Lm^-1.
  Eigen::MatrixXd T = Lm.transpose().triangularView<Eigen::Upper>().solve(inner);
  out.variance =
      Lm.transpose().triangularView<Eigen::Upper>().solve(T.transpose()).transpose();
  out.variance = 0.5 * (out.variance + out.variance.transpose());
  if (!out.weights.allFinite() || !out.variance.allFinite()) {
    return Status::Error("the residual layer's posterior is not finite");
  }
  if (fit != nullptr) {
    fit->hyperparameter_rows = N;
    fit->iterations = iterations;
    fit->log_marginal_likelihood =
        internal::GpLogMarginalLikelihood(theta, with_tool, X, sub_tools, Y, nullptr);
    double before = 0, after = 0;
    for (int r = 0; r < rows; ++r) {
      before += residuals[r].squaredNorm();
      after += (residuals[r] - out.Mean(qrow(r), tools[r])).squaredNorm();
    }
    fit->residual_rms_before = std::sqrt(before / rows);
    fit->residual_rms_after = std::sqrt(after / rows);
  }
  *layer = std::move(out);
  return Status::Ok();
}

}  // namespace lpoe
