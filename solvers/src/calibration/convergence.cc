#include "lpoe/convergence.h"

#include <cmath>
#include <cstdio>

#include <Eigen/Cholesky>

namespace lpoe {

const char* StopRuleName(StopRule rule) {
  switch (rule) {
    case StopRule::kNone:
      return "none";
    case StopRule::kAbsoluteStep:
      return "absolute step";
    case StopRule::kStatisticalStep:
      return "step below the standard deviations";
    case StopRule::kRelativeStep:
      return "step relative to the parameters";
    case StopRule::kCost:
      return "relative cost change";
  }
  return "unknown";
}

double ParameterScale(const RobotModel& model) {
  double s = 0;
  for (const Joint& j : model.joints) s += j.origin.t.squaredNorm() + 1.0;
  for (const Tool& t : model.tools) s += t.origin.t.squaredNorm() + 1.0;
  return std::sqrt(s);
}

namespace {

// Rows k..n-1 of column k of L^-1 for a lower-triangular L (n x n, leading dimension ld; the
// strict upper triangle is not read) into x[k..n): L x = e_k solved forward from row k, since the
// column is zero above it. Plain loops over L's contiguous columns (the same operations as
// x.tail() -= x(m) L.col(m).tail(), without an expression per column). x[0..k) is neither read nor
// written.
inline void ForwardColumn(const double* L, Eigen::Index ld, Eigen::Index n, Eigen::Index k,
                          double* x) {
  for (Eigen::Index i = k; i < n; ++i) x[i] = 0.0;
  x[k] = 1.0;
  for (Eigen::Index m = k; m < n; ++m) {
    const double* Lm = L + m * ld;
    const double xm = x[m] / Lm[m];
    x[m] = xm;
    for (Eigen::Index i = m + 1; i < n; ++i) x[i] -= xm * Lm[i];
  }
}

// Column k of L^-1 (ForwardColumn).
inline void InverseFactorColumn(const Eigen::MatrixXd& L, Eigen::Index k, double* x) {
  ForwardColumn(L.data(), L.outerStride(), L.rows(), k, x);
}

}  // namespace

Eigen::VectorXd StandardDeviations(const Eigen::MatrixXd& H, double cost, long dof) {
  if (dof <= 0 || H.rows() == 0 || !(cost >= 0) || !std::isfinite(cost)) return {};
  // Column scaling keeps the factorization accurate (rotation columns carry ~10^3 mm lever arms).
  Eigen::VectorXd d(H.rows());
  for (Eigen::Index k = 0; k < H.rows(); ++k) {
    d(k) = H(k, k) > 0 ? 1.0 / std::sqrt(H(k, k)) : 1.0;
  }
  const Eigen::MatrixXd Hs = d.asDiagonal() * H * d.asDiagonal();
  Eigen::LLT<Eigen::MatrixXd> llt(Hs);
  if (llt.info() != Eigen::Success) return {};
  return StandardDeviationsFromFactor(llt.matrixLLT(), d, cost, dof);
}

Eigen::VectorXd StandardDeviationsFromFactor(const Eigen::MatrixXd& L, const Eigen::VectorXd& d,
                                             double cost, long dof) {
  if (dof <= 0 || L.rows() == 0 || !(cost >= 0) || !std::isfinite(cost)) return {};
  // diag(Hs^-1) only: Hs^-1 = L^-T L^-1, so (Hs^-1)_kk is the squared norm of column k of L^-1,
  // L x = e_k solved forward from row k (x is zero above it): n^3 / 6 multiply-adds instead of the
  // whole inverse's n^3.
  const Eigen::Index n = L.rows();
  Eigen::VectorXd x(n);
  const double s2 = 2.0 * cost / static_cast<double>(dof);
  Eigen::VectorXd sd(n);
  for (Eigen::Index k = 0; k < n; ++k) {
    InverseFactorColumn(L, k, x.data());
    sd(k) = d(k) * std::sqrt(std::max(0.0, s2 * x.tail(n - k).squaredNorm()));
  }
  if (!sd.allFinite()) return {};
  return sd;
}

// (L L^T)^-1 for a lower-triangular L (the strict upper triangle is not read): L^-1 column by
// column by forward substitution (column k is zero above row k), then L^-T L^-1 from the columns'
// dot products over the rows where both are non-zero: n^3 / 3 multiply-adds in all, against n^3 for
// two triangular solves with the identity. Exactly symmetric.
Eigen::MatrixXd InverseFromCholeskyFactor(const Eigen::MatrixXd& L) {
  const Eigen::Index n = L.rows();
  Eigen::MatrixXd Li = Eigen::MatrixXd::Zero(n, n);
  for (Eigen::Index k = 0; k < n; ++k) InverseFactorColumn(L, k, Li.col(k).data());
  Eigen::MatrixXd inv(n, n);
  for (Eigen::Index b = 0; b < n; ++b) {
    for (Eigen::Index a = b; a < n; ++a) {
      const double v = Li.col(a).tail(n - a).dot(Li.col(b).tail(n - a));
      inv(a, b) = v;
      inv(b, a) = v;
    }
  }
  return inv;
}

ConvergenceDecision TestConvergence(const ConvergenceOptions& o, const ConvergenceState& s) {
  ConvergenceDecision d;
  d.step_norm = s.step.norm();
  char buf[256];
  if (s.standard_deviation.size() == s.step.size() && s.step.size() > 0 &&
      (s.standard_deviation.array() > 0).all()) {
    d.step_in_sd = (s.step.array().abs() / s.standard_deviation.array()).maxCoeff();
  }
  if (d.step_norm < o.step_tolerance) {
    d.rule = StopRule::kAbsoluteStep;
    std::snprintf(buf, sizeof(buf), "converged: |x| = %.3g below the step tolerance %.3g",
                  d.step_norm, o.step_tolerance);
  } else if (d.step_in_sd > 0 && d.step_in_sd < o.sd_fraction) {
    d.rule = StopRule::kStatisticalStep;
    std::snprintf(buf, sizeof(buf),
                  "converged: the step (|x| = %.3g) is at most %.3g standard deviations of every "
                  "parameter (tolerance %.3g)",
                  d.step_norm, d.step_in_sd, o.sd_fraction);
  } else if (d.step_norm < o.relative_step_tolerance * s.parameter_scale) {
    d.rule = StopRule::kRelativeStep;
    std::snprintf(buf, sizeof(buf),
                  "converged: |x| = %.3g is below %.3g of the parameters' scale %.6g",
                  d.step_norm, o.relative_step_tolerance, s.parameter_scale);
  } else if (s.previous_cost >= 0 && s.cost > 0 &&
             s.previous_cost - s.cost <= o.relative_cost_tolerance * s.cost) {
    d.rule = StopRule::kCost;
    std::snprintf(buf, sizeof(buf),
                  "converged: the last step changed the cost by %.3g relative (tolerance %.3g; "
                  "|x| = %.3g)",
                  (s.previous_cost - s.cost) / s.cost, o.relative_cost_tolerance, d.step_norm);
  } else {
    return d;
  }
  d.message = buf;
  return d;
}

std::string ValidateConvergenceOptions(const ConvergenceOptions& o) {
  if (!(o.step_tolerance > 0 && o.step_tolerance <= 1)) {
    return "step_tolerance must be in (0, 1] (mm or rad)";
  }
  if (!(o.sd_fraction >= 0 && o.sd_fraction < 1)) return "sd_fraction must be in [0, 1)";
  if (!(o.relative_step_tolerance >= 0 && o.relative_step_tolerance < 1)) {
    return "relative_step_tolerance must be in [0, 1)";
  }
  if (!(o.relative_cost_tolerance >= 0 && o.relative_cost_tolerance < 1)) {
    return "relative_cost_tolerance must be in [0, 1)";
  }
  return "";
}

}  // namespace lpoe
