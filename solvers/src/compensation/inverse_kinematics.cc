#include "lpoe/inverse_kinematics.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <glog/logging.h>


#include "lpoe/terms/joint_errors.h"

namespace lpoe {
namespace {

constexpr int kMax = InverseKinematics::kMaxJoints;
// Weighted task error (mm) below which a step is accepted even if it raised the error.
constexpr double kNullSpaceSlack = 1e-2;
// Revolute-z joints: sin and cos of the joint value are carried from one iterate to the next by
// the addition theorem with the step's sin/cos from a series (|step| below kIncrementalStep, error
// below 1e-21), and recomputed by sincos after kIncrementalRefresh such updates (round-off of a few
// 1e-16 rad in all).
constexpr double kIncrementalStep = 0.25;
constexpr int kIncrementalRefresh = 8;
// The null-space pull toward the seed is halved (down to this) when successive steps reverse.
constexpr double kMinPull = 1.0 / 64;
// Square tasks: after a damped step (a rejected step before it; no step of the run cut at a joint
// limit) that achieved at least this fraction of the reduction of the merit its linear model
// predicted, the next step is Newton's again (damping zero) instead of a damping that decays by 10
// per step. The pull toward the seed in the damped step holds the error near lambda^2 times the
// pull, so a slowly decaying damping made the error fall by only 10 per iteration.
constexpr double kGoodModel = 0.75;

// sin(d), cos(d) for |d| <= kIncrementalStep: Taylor series to d^13 and d^14.
inline void SinCosSmall(double d, double* s, double* c) {
  const double d2 = d * d;
  *s = d * (1 + d2 * (-1.0 / 6 + d2 * (1.0 / 120 + d2 * (-1.0 / 5040 + d2 * (1.0 / 362880 +
       d2 * (-1.0 / 39916800 + d2 * (1.0 / 6227020800.0)))))));
  *c = 1 + d2 * (-0.5 + d2 * (1.0 / 24 + d2 * (-1.0 / 720 + d2 * (1.0 / 40320 +
       d2 * (-1.0 / 3628800 + d2 * (1.0 / 479001600 + d2 * (-1.0 / 87178291200.0)))))));
}

// The same for the small steps of the last iterations: below 0.01 rad the series to d^7 and d^8
// (next terms below 3e-24) replace the long one.
inline void SinCosStep(double d, double* s, double* c) {
  const double d2 = d * d;
  if (d2 < 1e-4) {
    *s = d * (1 + d2 * (-1.0 / 6 + d2 * (1.0 / 120 + d2 * (-1.0 / 5040))));
    *c = 1 + d2 * (-0.5 + d2 * (1.0 / 24 + d2 * (-1.0 / 720 + d2 * (1.0 / 40320))));
    return;
  }
  SinCosSmall(d, s, c);
}

// sin and cos of x[j] for the `count` joints j in idx, into s[j] and c[j]: gathered into one
// SinCosMany call (four values per SLEEF call where the processor has AVX2 and FMA; each
// value's result depends on that value only, so both paths get the same bits).
inline void SinCosOf(const double* x, const int* idx, int count, double* s, double* c) {
  if (count == 0) return;
  double xs[kMax], ss[kMax], cs[kMax];
  for (int k = 0; k < count; ++k) xs[k] = x[idx[k]];
  SinCosMany(xs, count, ss, cs);
  for (int k = 0; k < count; ++k) {
    s[idx[k]] = ss[k];
    c[idx[k]] = cs[k];
  }
}

// log(R_target R^T)^vee. Near the target (angle below 0.01 rad) from the skew part alone:
// v = sin(theta) axis and theta / sin(theta) = arcsin(s) / s = 1 + s^2/6 + 3 s^4/40 + 5 s^6/112 +
// 35 s^8/1152 (s = |v|; the next term is below 1e-21), without the quaternion and atan2 of LogSO3;
// below 0.2 rad the longer series.
inline Eigen::Vector3d RotationError(const Eigen::Matrix3d& R_target, const Eigen::Matrix3d& R) {
  const Eigen::Matrix3d E = R_target * R.transpose();
  const Eigen::Vector3d v(0.5 * (E(2, 1) - E(1, 2)), 0.5 * (E(0, 2) - E(2, 0)),
                          0.5 * (E(1, 0) - E(0, 1)));
  const double s2 = v.squaredNorm();
  if (s2 < 1e-4 && E.trace() > 1) {
    return v * (1 + s2 * (1.0 / 6 + s2 * (3.0 / 40 + s2 * (5.0 / 112 + s2 * (35.0 / 1152)))));
  }
  // Up to 0.2 rad (the first iterates from seeds a few degrees away): the same series to s^22
  // (coefficients C(2k, k) / (4^k (2k + 1)); the next term below 3e-18).
  if (s2 < 0.04 && E.trace() > 1) {
    return v * (1 + s2 * (1.0 / 6 + s2 * (3.0 / 40 + s2 * (5.0 / 112 + s2 * (35.0 / 1152 +
                s2 * (63.0 / 2816 + s2 * (231.0 / 13312 + s2 * (143.0 / 10240 +
                s2 * (6435.0 / 557056 + s2 * (12155.0 / 1245184 + s2 * (46189.0 / 5505024 +
                s2 * (88179.0 / 12058624))))))))))));
  }
  return LogSO3<double>(E);
}

// Newton's step of a regular square task, and its second-order correction with the same factors:
// Eigen's LU with partial pivoting of the M x M Jacobian (column-major, A[M c + r]). Ok() false when
// a pivot is below `tiny` (then the damped form is used).
template <int M>
class SquareLu {
 public:
  using MatM = Eigen::Matrix<double, M, M>;
  SquareLu(const double* A, double tiny) : lu_(Eigen::Map<const MatM>(A)) {
    ok_ = lu_.matrixLU().diagonal().cwiseAbs().minCoeff() > tiny;
  }
  bool Ok() const { return ok_; }
  // d = A^-1 b (d may alias b).
  void Solve(const double* b, double* d) const {
    const Eigen::Matrix<double, M, 1> x = lu_.solve(Eigen::Map<const Eigen::Matrix<double, M, 1>>(b));
    Eigen::Map<Eigen::Matrix<double, M, 1>> out(d);
    out = x;
  }

 private:
  Eigen::PartialPivLU<MatM> lu_;
  bool ok_ = true;
};

// The second-order term Q(dx) of the weighted pose error along a step dx of the chain's joint
// values, from the weighted Jacobian Jx (6 x n, column-major; column j is (u_j, L w_j): the tool
// point's velocity and L times the axis). With the axes at x, FK(x + dx) = exp(dx_1 xi_1) ...
// exp(dx_n xi_n) FK(x) (spatial twists xi_j), so with b_j = dx_j w_j and a_j = dx_j u_j
//   p(x + dx) - p          = sum_j a_j + sum_i b_i x (a_i / 2 + sum_{j>i} a_j) + O(dx^3),
//   log(R(x + dx) R(x)^T)  = sum_j b_j + 1/2 sum_i b_i x sum_{j>i} b_j + O(dx^3)  (Baker-Campbell-
// Hausdorff), and Q = [the second-order position term; L times the second-order rotation term].
// One backward pass of cross products (prismatic joints: w_j = 0, the formulas hold as they are).
inline void PoseSecondOrder(const double* Jx, const double* dx, int n, double L, double* Q) {
  double sa[3] = {0, 0, 0}, sb[3] = {0, 0, 0}, qp[3] = {0, 0, 0}, qr[3] = {0, 0, 0};
  const double inv_l = 1 / L;
  for (int i = n - 1; i >= 0; --i) {
    const double* c = Jx + 6 * i;
    const double t = dx[i] * inv_l;
    const double a[3] = {dx[i] * c[0], dx[i] * c[1], dx[i] * c[2]};
    const double b[3] = {t * c[3], t * c[4], t * c[5]};
    const double h[3] = {0.5 * a[0] + sa[0], 0.5 * a[1] + sa[1], 0.5 * a[2] + sa[2]};
    qp[0] += b[1] * h[2] - b[2] * h[1];
    qp[1] += b[2] * h[0] - b[0] * h[2];
    qp[2] += b[0] * h[1] - b[1] * h[0];
    qr[0] += b[1] * sb[2] - b[2] * sb[1];
    qr[1] += b[2] * sb[0] - b[0] * sb[2];
    qr[2] += b[0] * sb[1] - b[1] * sb[0];
    for (int r = 0; r < 3; ++r) {
      sa[r] += a[r];
      sb[r] += b[r];
    }
  }
  const double half_l = 0.5 * L;
  for (int r = 0; r < 3; ++r) {
    Q[r] = qp[r];
    Q[3 + r] = half_l * qr[r];
  }
}

// Newton's step of a square pose task (6 x 6, weighted J = Jx dg/dq, error e) with its second-order
// correction: d0 = J^-1 e, then d = d0 - J^-1 Q(dg/dq d0) (Chebyshev's method: the error after the
// step is of third order in d0 instead of second). The correction is dropped when it is not small
// against the step (|c|_inf > |d0|_inf / 2: far from the solution, where the expansion says
// nothing). Jx: the Jacobian before the chain rule; dg_dq: null for the identity.
inline void CorrectedNewtonStep6(const SquareLu<6>& lu, const double* e, const double* Jx,
                                 const double* dg_dq, double L, double* d) {
  lu.Solve(e, d);
  double dx[6], Q[6], c[6];
  const double* step = d;
  if (dg_dq != nullptr) {
    for (int r = 0; r < 6; ++r) {
      double v = 0;
      for (int k = 0; k < 6; ++k) v += dg_dq[6 * k + r] * d[k];
      dx[r] = v;
    }
    step = dx;
  }
  PoseSecondOrder(Jx, step, 6, L, Q);
  lu.Solve(Q, c);
  double dmax = 0, cmax = 0;
  for (int j = 0; j < 6; ++j) {
    dmax = std::max(dmax, std::abs(d[j]));
    cmax = std::max(cmax, std::abs(c[j]));
  }
  if (cmax <= 0.5 * dmax) {
    for (int j = 0; j < 6; ++j) d[j] -= c[j];
  }
}

// Smallest eigenvalue of the Gram matrix A = J J^T of an M x n column-major J (sigma_min^2 of J for
// M <= n; a diagnostic and a threshold). Householder reflections reduce A to a tridiagonal T with the same
// eigenvalues; Laguerre's iteration on det(T - x I) then climbs from x = 0 to the smallest one. For
// a polynomial with only real roots, Laguerre's step from below the smallest root stays below it
// and converges to it monotonically, cubically (in one step when all roots coincide), so no test of
// which eigenvalue was found is needed. Its sums G = sum_i 1 / (lambda_i - x) and
// H = sum_i 1 / (lambda_i - x)^2 come from the leading principal minors p_i of T - x I (the
// three-term recurrence, differentiated twice); all p_i positive (so all pivots p_i / p_{i-1} of
// its LDL^T) is the proof that x is below the smallest eigenvalue (Sylvester's law of inertia). 0
// when A is singular to round-off (a minor of T itself not positive).
template <int M>
double SmallestEigenvalueOfGram(const double* J, int n) {
  // A = J J^T (lower triangle, A[i][j] for j <= i, read), as a sum of the columns' outer products.
  double A[M][M];
  {
    for (int i = 0; i < M; ++i) {
      for (int j = 0; j < M; ++j) A[i][j] = 0;
    }
    for (int k = 0; k < n; ++k) {
      const double* c = J + M * k;
#pragma GCC unroll 6
      for (int i = 0; i < M; ++i) {
#pragma GCC unroll 6
        for (int j = 0; j <= i; ++j) A[i][j] += c[i] * c[j];
      }
    }
  }
  auto at = [&A](int i, int j) -> double& { return i >= j ? A[i][j] : A[j][i]; };
  double diag[M], off2[M];  // T's diagonal and squared off-diagonal
#pragma GCC unroll 4
  for (int k = 0; k + 2 < M; ++k) {
    // The reflection H = I - beta v v^T that zeroes A[k+2.., k]; A <- H A H on rows/columns k+1...
    double s = 0;
    for (int i = k + 2; i < M; ++i) s += A[i][k] * A[i][k];
    const double x0 = A[k + 1][k];
    if (s == 0) {  // already tridiagonal in this column
      off2[k] = x0 * x0;
      continue;
    }
    const double norm = std::sqrt(x0 * x0 + s);
    const double alpha = x0 > 0 ? -norm : norm;
    double v[M], p[M];
    v[k + 1] = x0 - alpha;
    for (int i = k + 2; i < M; ++i) v[i] = A[i][k];
    const double beta = 1 / (norm * norm - x0 * alpha);  // 2 / (v^T v)
    double vp = 0;
#pragma GCC unroll 6
    for (int i = k + 1; i < M; ++i) {
      double t = 0;
#pragma GCC unroll 6
      for (int j = k + 1; j < M; ++j) t += at(i, j) * v[j];
      p[i] = beta * t;
      vp += v[i] * p[i];
    }
    const double half = 0.5 * beta * vp;
    for (int i = k + 1; i < M; ++i) p[i] -= half * v[i];
#pragma GCC unroll 6
    for (int i = k + 1; i < M; ++i) {
#pragma GCC unroll 6
      for (int j = k + 1; j <= i; ++j) A[i][j] -= v[i] * p[j] + p[i] * v[j];
    }
    off2[k] = alpha * alpha;
  }
  if (M >= 2) off2[M - 2] = A[M - 1][M - 2] * A[M - 1][M - 2];
  for (int i = 0; i < M; ++i) diag[i] = A[i][i];

  // Laguerre's step at x from the leading principal minors of T - x I, p_i = (a_i - x) p_{i-1} -
  // b_{i-1}^2 p_{i-2}, and their first two derivatives in x (p = p_M = prod (lambda_i - x)):
  // with G = -p'/p and H = G^2 - p''/p, the step M / (G + sqrt((M-1)(M H - G^2))) is, multiplied
  // through by p > 0, M p / (-p' + sqrt((M-1)((M-1) p'^2 - M p p''))): one division (the step's)
  // on the iteration's chain, none on the recurrence's. False when a minor is not positive (then a
  // pivot p_i / p_{i-1} is not: x is not below every eigenvalue). The entries (mm^2) keep p and
  // p'^2 far from overflow.
  auto step_at = [&](double x, double* step) {
    double p1 = 1, d1 = 0, e1 = 0;  // p_{i-1}, p'_{i-1}, p''_{i-1}
    double p2 = 0, d2 = 0, e2 = 0;  // p_{i-2}, ...
    bool positive = true;
#pragma GCC unroll 6
    for (int i = 0; i < M; ++i) {
      const double t = diag[i] - x, b2 = i > 0 ? off2[i - 1] : 0.0;
      const double p = t * p1 - b2 * p2;
      const double d = t * d1 - p1 - b2 * d2;
      const double e = t * e1 - 2 * d1 - b2 * e2;
      positive &= p > 0;
      p2 = p1;
      d2 = d1;
      e2 = e1;
      p1 = p;
      d1 = d;
      e1 = e;
    }
    if (!positive) return false;
    const double root = std::sqrt(std::max(0.0, (M - 1) * ((M - 1) * (d1 * d1) - M * (p1 * e1))));
    *step = M * p1 / (root - d1);
    return true;
  };
  double step;
  if (!step_at(0.0, &step)) return 0.0;
  double x = 0;
  for (int k = 0; k < 100; ++k) {
    const double next = x + step;
    // Converged: the convergence is cubic, so after a step below 1e-6 of x what is left is of the
    // order of 1e-18 of it (times the spread of the eigenvalues; far below the 1e-13 the routine
    // resolves, and one evaluation of the sums fewer than with the next step's 1e-18). Or `next`
    // lies on the eigenvalue to round-off (a minor not positive there).
    if (!(step > 1e-6 * next) || !step_at(next, &step)) return next;
    x = next;
  }
  return x;
}

// y <- A^-1 y for the M x M symmetric positive semi-definite A of a damped step (A's diagonal already
// holds the damping and 1e-13 of its mean; `trace` is A's trace before them). M = 3 (position
// tasks): Eigen's closed-form inverse of a fixed 3 x 3 matrix (cofactors; inlined, unlike the
// factorization's loops), else Eigen's LLT. A rank-deficient A to round-off is regularized more (1e-9
// of its mean diagonal); y = 0 if that fails too.
template <int M>
void SolveRegularized(Eigen::Matrix<double, M, M>* A, double trace, Eigen::Matrix<double, M, 1>* y) {
  if constexpr (M == 3) {
    for (int attempt = 0; attempt < 2; ++attempt) {
      // The determinant and the inverse from one set of cofactors.
      Eigen::Matrix<double, M, M> inverse = Eigen::Matrix<double, M, M>::Zero();  // set if invertible
      double det = 0;
      bool invertible = false;
      A->computeInverseAndDetWithCheck(inverse, det, invertible, 0.0);
      if (det > 0 && std::isfinite(det)) {
        *y = inverse * *y;
        return;
      }
      A->diagonal().array() += 1e-9 * std::max(trace, 1e-30) / M;
    }
    y->setZero();
  } else {
    Eigen::LLT<Eigen::Matrix<double, M, M>> llt(*A);
    if (llt.info() != Eigen::Success) {
      A->diagonal().array() += 1e-9 * std::max(trace, 1e-30) / M;
      llt.compute(*A);
    }
    if (llt.info() == Eigen::Success) {
      llt.solveInPlace(*y);
    } else {
      y->setZero();
    }
  }
}

int Sign(double x) { return x > 0 ? 1 : (x < 0 ? -1 : 0); }

// (D_arm, D_wrist) signs from the frames of one configuration (see the header): the joint Jacobian
// of the point c (the first three position columns) and the last three joint axes.
void BranchSignsOf(const KinematicChain& chain, const FrameRt* frames, int signs[2]) {
  const int n = chain.num_joints();
  FrameRt at_c[kMax + 1];
  std::copy(frames, frames + n, at_c);
  at_c[n].t = frames[n - 2].t;
  Eigen::Matrix<double, 6, Eigen::Dynamic, 0, 6, kMax> J(6, n);
  chain.ToolJointJacobian(at_c, J.data(), 6);
  signs[0] = Sign(J.topLeftCorner<3, 3>().determinant());
  const Eigen::Matrix3d axes = J.bottomRightCorner<3, 3>();
  signs[1] = Sign(axes.determinant());
}

// The joint-error terms a model carries (RobotModel::joint_errors): g(q) = q + dq(q), dg/dq by
// forward differences of dq (its derivatives are of the order of the offsets themselves, 1e-4, so
// the differences' error is far below what would slow Newton's convergence).
class ModelJointErrors : public EffectiveJointMap {
 public:
  explicit ModelJointErrors(const RobotModel& model) : model_(&model) {}
  void Evaluate(const double* q, double* q_eff, double* dg_dq) const override {
    const int n = model_->num_joints();
    double dq[kMax], qh[kMax], dqh[kMax];
    JointErrorOffsets(*model_, q, dq);
    for (int j = 0; j < n; ++j) q_eff[j] = q[j] + dq[j];
    if (dg_dq == nullptr) return;
    constexpr double kStep = 1e-6;  // rad or mm
    for (int j = 0; j < n; ++j) qh[j] = q[j];
    for (int c = 0; c < n; ++c) {
      qh[c] = q[c] + kStep;
      JointErrorOffsets(*model_, qh, dqh);
      qh[c] = q[c];
      for (int r = 0; r < n; ++r) dg_dq[c * n + r] = (r == c) + (dqh[r] - dq[r]) / kStep;
    }
  }

 private:
  const RobotModel* model_;
};

}  // namespace

const char* IkStatusName(IkStatus status) {
  switch (status) {
    case IkStatus::kOk:
      return "ok";
    case IkStatus::kUnreachable:
      return "unreachable";
    case IkStatus::kLimit:
      return "limit";
    case IkStatus::kSingular:
      return "singular";
    case IkStatus::kBranch:
      return "branch";
  }
  return "unknown";
}

Status InverseKinematics::CheckModel(const RobotModel& model) {
  if (Status s = model.Validate(); !s.ok()) return s;
  if (model.num_joints() > kMax) {
    return Status::Error("inverse kinematics supports at most " + std::to_string(kMax) +
                         " joints; the model has " + std::to_string(model.num_joints()));
  }
  for (const Joint& j : model.joints) {
    if (j.lower > j.upper) {
      return Status::Error("joint " + j.name + ": lower limit above upper limit");
    }
  }
  return Status::Ok();
}

InverseKinematics::InverseKinematics(const RobotModel& model, const IkOptions& options,
                                     const EffectiveJointMap* effective)
    : model_(&model), options_(options), effective_(effective), chain_(model) {
  CHECK(CheckModel(model).ok()) << CheckModel(model).message();
  if (effective_ == nullptr && !model.joint_errors.empty()) {
    own_effective_ = std::make_shared<ModelJointErrors>(model);
    effective_ = own_effective_.get();
  }
  const int n = model.num_joints();
  for (int j = 0; j < n; ++j) z_revolute_[j] = IsRevoluteZ(model.joints[j]);
  branch_defined_ = n >= 6;
  if (branch_defined_) {
    for (int j : {0, 1, 2, n - 3, n - 2, n - 1}) {
      if (model.joints[j].type != JointType::kRevolute) branch_defined_ = false;
    }
  }
}

void InverseKinematics::BranchSigns(const double* q, int signs[2]) const {
  signs[0] = signs[1] = 0;
  if (!branch_defined_) return;
  FrameRt frames[kMax + 1];
  double q_eff[kMax];
  const double* x = q;
  if (effective_ != nullptr) {
    effective_->Evaluate(q, q_eff, nullptr);
    x = q_eff;
  }
  chain_.Frames(x, 0, frames);
  BranchSignsOf(chain_, frames, signs);
}

IkResult InverseKinematics::Solve(const IkTarget& target, const double* seed, double* q) const {
  if (model_->residual_layer) return SolveThroughLayer(target, seed, q);
  return SolveParametric(target, seed, q);
}

IkResult InverseKinematics::SolveParametric(const IkTarget& target, const double* seed,
                                            double* q) const {
  CHECK(target.tool >= 0 && target.tool < model_->num_tools()) << "tool index " << target.tool;
  const int n = chain_.num_joints();
  if (target.has_orientation) {
    if (n == 6) return SolveTask<6, 6>(target, seed, q);
    if (n == 7) return SolveTask<6, 7>(target, seed, q);
    return SolveTask<6, Eigen::Dynamic>(target, seed, q);
  }
  if (n == 6) return SolveTask<3, 6>(target, seed, q);
  if (n == 7) return SolveTask<3, 7>(target, seed, q);
  return SolveTask<3, Eigen::Dynamic>(target, seed, q);
}

namespace {

// One damped Newton run (InverseKinematics::Run) on the solver's chain, joint map and options: the
// limits, step caps and seed of the solve, the iterates' evaluation (chain, task error, Jacobian),
// the step and the result.
template <int M, int N>
struct IkRun {
  static constexpr int kMaxN = N == Eigen::Dynamic ? kMax : N;
  using MatJ = Eigen::Matrix<double, M, N, 0, M, kMaxN>;
  using VecN = Eigen::Matrix<double, N, 1, 0, kMaxN, 1>;
  using VecM = Eigen::Matrix<double, M, 1>;
  using MatM = Eigen::Matrix<double, M, M>;

  // One iterate: joints, the chain's joint values x (q, or g(q) with joint-space terms) with their
  // sin/cos, frames, weighted task error and Jacobian.
  struct Iterate {
    VecN q;
    double x[kMax], sin_x[kMax], cos_x[kMax];
    int age[kMax];  // incremental sin/cos updates since the last sincos
    FrameRt frames[kMax + 1];
    VecM e;
    MatJ J;
    double merit = 0;
    // Square pose tasks with a joint map: J before the chain rule, and dg/dq (the second order).
    double Jx[M == 6 && N == 6 ? 36 : 1], dg_dq[M == 6 && N == 6 ? 36 : 1];
  };

  IkRun(const RobotModel& model, const KinematicChain& kinematic_chain,
        const EffectiveJointMap* joint_map, const bool* revolute_z, const IkOptions& options,
        const IkTarget& task, const double* seed_in)
      : chain(kinematic_chain),
        effective(joint_map),
        z_revolute(revolute_z),
        target(task),
        o(options),
        n(kinematic_chain.num_joints()),
        L(o.orientation_weight),
        redundant(n > M) {
    lower.resize(n);
    upper.resize(n);
    max_step.resize(n);
    seed.resize(n);
    for (int j = 0; j < n; ++j) {
      const Joint& joint = model.joints[j];
      lower(j) = o.respect_limits ? joint.lower : -HUGE_VAL;
      upper(j) = o.respect_limits ? joint.upper : HUGE_VAL;
      max_step(j) = joint.type == JointType::kRevolute ? o.max_step_revolute : o.max_step_prismatic;
      seed(j) = std::min(std::max(seed_in[j], lower(j)), upper(j));
    }
  }

  bool TaskOk(const VecM& e) const {
    if (e.template head<3>().norm() > o.position_tolerance) return false;
    if constexpr (M == 6) {
      if (e.template tail<3>().norm() > L * o.orientation_tolerance) return false;
    }
    return true;
  }

  // Evaluates `it` at it->q; `from` (or null) is the iterate whose sin/cos are carried over.
  void Evaluate(const Iterate* from, Iterate* it) const {
    double dg_dq[kMax * kMax];
    if (effective != nullptr) {
      effective->Evaluate(it->q.data(), it->x, dg_dq);
    } else {
      for (int j = 0; j < n; ++j) it->x[j] = it->q(j);
    }
    int fresh[kMax], count = 0;  // joints whose sin/cos are computed afresh
    for (int j = 0; j < n; ++j) {
      if (!z_revolute[j]) continue;
      const double delta = from != nullptr ? it->x[j] - from->x[j] : HUGE_VAL;
      if (std::abs(delta) <= kIncrementalStep && from->age[j] < kIncrementalRefresh) {
        double sd, cd;
        SinCosStep(delta, &sd, &cd);
        it->sin_x[j] = from->sin_x[j] * cd + from->cos_x[j] * sd;
        it->cos_x[j] = from->cos_x[j] * cd - from->sin_x[j] * sd;
        it->age[j] = from->age[j] + 1;
      } else {
        fresh[count++] = j;
        it->age[j] = 0;
      }
    }
    SinCosOf(it->x, fresh, count, it->sin_x, it->cos_x);
    chain.Frames(it->x, it->sin_x, it->cos_x, target.tool, it->frames);
    const FrameRt& T = it->frames[n];
    it->e.template head<3>() = target.position - T.t;
    it->J.resize(M, n);
    if constexpr (M == 6) {
      chain.ToolJointJacobian(it->frames, it->J.data(), 6);
      it->J.template bottomRows<3>() *= L;
      it->e.template tail<3>() = L * RotationError(target.rotation, T.R);
    } else {
      chain.ToolJointJacobian(it->frames, it->J.data(), 3, 3);
    }
    if (effective != nullptr) ApplyJointMap(dg_dq, it);
    it->merit = it->e.squaredNorm();
  }

  // J <- J dg/dq (the chain rule of the joint map); square pose tasks keep J and dg/dq.
  void ApplyJointMap(const double* dg_dq, Iterate* it) const {
    if constexpr (M == 6 && N == 6) {
      std::copy(dg_dq, dg_dq + 36, it->dg_dq);
      std::copy(it->J.data(), it->J.data() + 36, it->Jx);
      double* J = it->J.data();
      for (int c = 0; c < 6; ++c) {
        for (int r = 0; r < 6; ++r) {
          double v = 0;
          for (int k = 0; k < 6; ++k) v += it->Jx[6 * k + r] * dg_dq[6 * c + k];
          J[6 * c + r] = v;
        }
      }
    } else {
      const Eigen::Map<const Eigen::Matrix<double, N, N, 0, kMaxN, kMaxN>> G(dg_dq, n, n);
      const MatJ Jq = it->J * G;
      it->J = Jq;
    }
  }

  // A square task, undamped, no joint held: Newton's step J d = e (the pull toward the seed has
  // no null space to act in); false when J is singular to round-off.
  bool NewtonStep(const Iterate& cur, VecN* d) const {
    if constexpr (N == M) {
      const MatJ& J = cur.J;
      const double tiny = 1e-9 * std::max(J.template lpNorm<Eigen::Infinity>(), 1e-30);
      const SquareLu<M> lu(J.data(), tiny);
      if (!lu.Ok()) return false;
      if constexpr (M == 6) {  // with the second-order correction
        const bool mapped = effective != nullptr;
        CorrectedNewtonStep6(lu, cur.e.data(), mapped ? cur.Jx : J.data(),
                             mapped ? cur.dg_dq : nullptr, L, d->data());
      } else {
        lu.Solve(cur.e.data(), d->data());
      }
      return true;
    } else {
      return false;
    }
  }

  // The damped step (see the header) with the joints in `locked` held at q + fixed.
  void DampedStep(const Iterate& cur, double lambda2, double beta, const bool* locked,
                  bool any_locked, const VecN& fixed, MatJ* Jf, VecN* d) const {
    const MatJ& J = cur.J;
    if (any_locked) *Jf = J;
    const MatJ& Ju = any_locked ? *Jf : J;  // columns of the joints still free
    VecM rhs = cur.e;
    VecN r = beta * (seed - cur.q);
    if (any_locked) {
      for (int j = 0; j < n; ++j) {
        if (!locked[j]) continue;
        rhs -= J.col(j) * fixed(j);
        Jf->col(j).setZero();
        r(j) = 0;
      }
    }
    MatM A = Ju * Ju.transpose();
    const double trace = A.trace();
    A.diagonal().array() += lambda2 + (trace > 0 ? 1e-13 * trace / M : 1e-30);
    VecM y = rhs - Ju * r;
    SolveRegularized(&A, trace, &y);
    *d = r + Ju.transpose() * y;
    for (int j = 0; j < n; ++j) {
      if (locked[j]) (*d)(j) = fixed(j);
    }
  }

  // One damped step with the active set of limits (see the header) from `cur`, into *d.
  void ComputeStep(const Iterate& cur, double lambda2, double beta, VecN* d) {
    const VecN& q = cur.q;
    bool locked[kMax] = {};
    bool any_locked = false;
    VecN fixed = VecN::Zero(n);
    MatJ Jf;
    for (int round = 0; round <= n; ++round) {
      const bool solved = !any_locked && lambda2 == 0 && NewtonStep(cur, d);
      if (!solved) DampedStep(cur, lambda2, beta, locked, any_locked, fixed, &Jf, d);
      // Trust region: scale the whole step (a move toward a limit stays inside when scaled).
      double scale = 1.0;
      for (int j = 0; j < n; ++j) {
        const double a = std::abs((*d)(j));
        if (a > max_step(j)) scale = std::min(scale, max_step(j) / a);
      }
      if (scale < 1.0) *d *= scale;
      if (!o.respect_limits) return;
      bool changed = false;
      for (int j = 0; j < n; ++j) {
        if (locked[j]) continue;
        const double x = q(j) + (*d)(j);
        if (x > upper(j) || x < lower(j)) {
          locked[j] = true;
          any_locked = true;
          fixed(j) = (x > upper(j) ? upper(j) : lower(j)) - q(j);
          changed = true;
          limit_hit = true;
        }
      }
      if (!changed) return;
    }
  }

  // The result at the final iterate: errors, sigma_min, branch, status; the joints into q_out.
  IkResult Finish(const Iterate& cur, bool converged, int iterations, bool check_branch,
                  const int seed_signs[2], const double* seed_in, double* q_out) const {
    IkResult result;
    // Smallest singular value of the weighted task Jacobian at q.
    const MatJ& J = cur.J;
    if (M <= n) {
      result.sigma_min = std::sqrt(SmallestEigenvalueOfGram<M>(J.data(), n));
    } else {
      const Eigen::Matrix<double, N, N, 0, kMaxN, kMaxN> A = J.transpose() * J;
      Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, N, N, 0, kMaxN, kMaxN>> eig(
          A, Eigen::EigenvaluesOnly);
      result.sigma_min = std::sqrt(std::max(0.0, eig.eigenvalues()(0)));
    }
    result.position_error = cur.e.template head<3>().norm();
    if constexpr (M == 6) result.orientation_error = cur.e.template tail<3>().norm() / L;
    result.iterations = iterations;
    double corr2 = 0;
    for (int j = 0; j < n; ++j) {
      const double qj = cur.q(j);
      q_out[j] = qj;
      if (qj == lower(j) || qj == upper(j)) result.at_limit = true;
      corr2 += (qj - seed_in[j]) * (qj - seed_in[j]);
    }
    result.correction = std::sqrt(corr2);
    if (check_branch) {
      int signs[2];
      BranchSignsOf(chain, cur.frames, signs);
      result.branch_changed = (seed_signs[0] != 0 && signs[0] != seed_signs[0]) ||
                              (seed_signs[1] != 0 && signs[1] != seed_signs[1]);
    }
    const bool singular = result.sigma_min < o.singular_threshold;
    if (converged) {
      result.status = singular                ? IkStatus::kSingular
                      : result.branch_changed ? IkStatus::kBranch
                                              : IkStatus::kOk;
    } else {
      result.status = result.at_limit || limit_hit ? IkStatus::kLimit
                      : singular                   ? IkStatus::kSingular
                                                   : IkStatus::kUnreachable;
    }
    return result;
  }

  const KinematicChain& chain;
  const EffectiveJointMap* effective;
  const bool* z_revolute;
  const IkTarget& target;
  const IkOptions& o;
  const int n;
  const double L;
  const bool redundant;
  VecN lower, upper, max_step, seed;
  bool limit_hit = false;  // some step of this run was cut at a joint limit
};

}  // namespace

template <int M, int N>
IkResult InverseKinematics::SolveTask(const IkTarget& target, const double* seed,
                                      double* q_out) const {
  const int n = chain_.num_joints();
  double start[kMax], best_q[kMax], trial_q[kMax];
  std::copy(seed, seed + n, start);
  IkResult best = Run<M, N>(target, seed, seed, best_q);
  auto reached = [](const IkResult& r) {
    return r.status == IkStatus::kOk || r.status == IkStatus::kBranch ||
           r.status == IkStatus::kSingular;
  };
  int iterations = best.iterations;
  uint64_t state = 0x9E3779B97F4A7C15ull;  // deterministic restarts (xorshift64)
  int k = 1;
  for (; k <= options_.restarts && !reached(best); ++k) {
    for (int j = 0; j < n; ++j) {
      state ^= state << 13;
      state ^= state >> 7;
      state ^= state << 17;
      const double u = static_cast<double>(state >> 11) * 0x1.0p-53 * 2 - 1;
      const double a = options_.restart_step * k *
                       (model_->joints[j].type == JointType::kRevolute ? 1.0 : 10.0);
      start[j] = seed[j] + a * u;
    }
    IkResult r = Run<M, N>(target, seed, start, trial_q);
    iterations += r.iterations;
    // Keep a reached solution closest to the seed; among unreached, the smallest error.
    const bool better =
        reached(r) ? (!reached(best) || (r.status == IkStatus::kOk && best.status != IkStatus::kOk) ||
                      (r.status == best.status && r.correction < best.correction))
                   : (!reached(best) && r.position_error < best.position_error);
    if (better) {
      best = r;
      std::copy(trial_q, trial_q + n, best_q);
    }
  }
  best.iterations = iterations;
  best.restarts = k - 1;
  std::copy(best_q, best_q + n, q_out);
  return best;
}

template <int M, int N>
IkResult InverseKinematics::Run(const IkTarget& target, const double* seed_in,
                                const double* start_in, double* q_out) const {
  using Context = IkRun<M, N>;
  using VecN = typename Context::VecN;
  Context ctx(*model_, chain_, effective_, z_revolute_, options_, target, seed_in);
  const IkOptions& o = options_;
  const int n = ctx.n;
  typename Context::Iterate iterates[2];
  typename Context::Iterate* cur = &iterates[0];
  typename Context::Iterate* trial = &iterates[1];

  cur->q.resize(n);
  trial->q.resize(n);
  for (int j = 0; j < n; ++j) {
    cur->q(j) = std::min(std::max(start_in[j], ctx.lower(j)), ctx.upper(j));
  }
  ctx.Evaluate(nullptr, cur);
  int seed_signs[2] = {0, 0};
  const bool check_branch = o.check_branch && branch_defined_;
  if (check_branch) {
    if (start_in == seed_in) {
      BranchSignsOf(chain_, cur->frames, seed_signs);
    } else {
      BranchSigns(ctx.seed.data(), seed_signs);
    }
  }

  bool converged = false;
  double lambda2 = 0, pull = 1, beta = 1;
  VecN d, d_prev;
  d.resize(n);
  d_prev.setZero(n);
  int it = 0;
  for (; it < o.max_iterations; ++it) {
    const bool ok = ctx.TaskOk(cur->e);
    if (ok && !ctx.redundant) {
      converged = true;
      break;
    }
    ctx.ComputeStep(*cur, lambda2, beta, &d);
    if (ok && d.template lpNorm<Eigen::Infinity>() < o.step_tolerance) {
      converged = true;
      break;
    }
    for (int j = 0; j < n; ++j) {
      trial->q(j) = std::min(std::max(cur->q(j) + d(j), ctx.lower(j)), ctx.upper(j));
    }
    // Square tasks, damped steps: the linear model's merit after the step (see kGoodModel).
    double predicted = 0;
    if constexpr (N == M) {
      if (lambda2 > 0) predicted = (cur->e - cur->J * d).squaredNorm();
    }
    ctx.Evaluate(cur, trial);
    // Near the target, a step toward the seed in the null space may raise the task error at
    // second order; the next step removes that, so such steps are accepted (kNullSpaceSlack).
    if (trial->merit <= cur->merit || trial->merit <= kNullSpaceSlack * kNullSpaceSlack ||
        ctx.TaskOk(trial->e)) {
      const bool model_good = N == M && lambda2 > 0 && !ctx.limit_hit &&
                              cur->merit - trial->merit >= kGoodModel * (cur->merit - predicted);
      std::swap(cur, trial);
      lambda2 *= 0.1;
      if (lambda2 < 1e-12 * cur->J.squaredNorm() / M || model_good) lambda2 = 0;
      // The pull toward the seed is a fixed-point iteration that overshoots (successive steps
      // reverse) where the task's curvature times its multiplier exceeds one, e.g. near a
      // singularity: halve it for the rest of the run.
      if (ctx.redundant && d.dot(d_prev) < -0.5 * d.norm() * d_prev.norm()) {
        pull = std::max(pull * 0.5, kMinPull);
      }
      d_prev = d;
      beta = pull;
    } else {
      const double scale = std::max(cur->J.squaredNorm() / M, 1e-30);
      lambda2 = std::max(lambda2 * 10, 1e-6 * scale);
      beta *= 0.5;
      if (lambda2 > 1e12 * scale) break;  // no step reduces the error: stalled
    }
  }
  // A redundant task whose null-space pull has not settled still reached the target.
  if (!converged && ctx.TaskOk(cur->e) && ctx.redundant) converged = true;
  return ctx.Finish(*cur, converged, it, check_branch, seed_signs, seed_in, q_out);
}

}  // namespace lpoe
