#include "lpoe/inverse_kinematics.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <glog/logging.h>

namespace lpoe {
namespace {

constexpr int kMax = InverseKinematics::kMaxJoints;
// Weighted task error (mm) below which a step is accepted even if it raised the error.
constexpr double kNullSpaceSlack = 1e-2;

// Spatial axis direction of revolute joint j from its frame G_j.
inline Eigen::Vector3d AxisOf(const Joint& joint, const FrameRt& G) {
  return IsRevoluteZ(joint) ? Eigen::Vector3d(G.R.col(2))
                            : Eigen::Vector3d(G.R * joint.twist.head<3>());
}

// Column j of the joint Jacobian (rows dp, drot) for frame G = G_j and tool point p.
inline void JointColumn(const Joint& joint, const FrameRt& G, const Eigen::Vector3d& p,
                        double* col) {
  const Eigen::Vector3d w = AxisOf(joint, G);
  Eigen::Map<Vector6d> out(col);
  out.head<3>() = w.cross(p - G.t);
  if (!IsRevoluteZ(joint)) out.head<3>() += G.R * joint.twist.tail<3>();
  out.tail<3>() = w;
}

// Smallest eigenvalue of a symmetric positive semi-definite M x M matrix: closed form for 3 x 3,
// else inverse iteration on its Cholesky factor (the Rayleigh quotient converges quadratically in
// the eigenvector; a fraction of the cost of a full eigendecomposition). 0 when A is singular.
template <int M>
double SmallestEigenvalue(const Eigen::Matrix<double, M, M>& A) {
  if constexpr (M == 3) {
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
    eig.computeDirect(A, Eigen::EigenvaluesOnly);
    return std::max(0.0, eig.eigenvalues()(0));
  } else {
    const Eigen::LLT<Eigen::Matrix<double, M, M>> llt(A);
    if (llt.info() != Eigen::Success) return 0.0;
    Eigen::Matrix<double, M, 1> x = Eigen::Matrix<double, M, 1>::Constant(1.0);
    x(0) = 1.3;  // not orthogonal to any axis-aligned eigenvector
    double rayleigh = HUGE_VAL;
    for (int k = 0; k < 12; ++k) {
      x.normalize();
      const double next = x.dot(A * x);
      if (k > 0 && std::abs(next - rayleigh) <= 1e-10 * rayleigh) return std::max(0.0, next);
      rayleigh = next;
      x = llt.solve(x);
      if (!x.allFinite() || x.squaredNorm() == 0) return 0.0;
    }
    return std::max(0.0, rayleigh);
  }
}

int Sign(double x) { return x > 0 ? 1 : (x < 0 ? -1 : 0); }

// (D_arm, D_wrist) signs from the frames of one configuration (see the header).
void BranchSignsOf(const RobotModel& model, const FrameRt* frames, int signs[2]) {
  const int n = model.num_joints();
  const Eigen::Vector3d c = frames[n - 2].t;
  Eigen::Matrix3d A;
  for (int j = 0; j < 3; ++j) {
    const Joint& joint = model.joints[j];
    const Eigen::Vector3d w = AxisOf(joint, frames[j]);
    A.col(j) = w.cross(c - frames[j].t);
    if (!IsRevoluteZ(joint)) A.col(j) += frames[j].R * joint.twist.tail<3>();
  }
  signs[0] = Sign(A.determinant());
  const Eigen::Vector3d a = AxisOf(model.joints[n - 3], frames[n - 3]);
  const Eigen::Vector3d b = AxisOf(model.joints[n - 2], frames[n - 2]);
  const Eigen::Vector3d d = AxisOf(model.joints[n - 1], frames[n - 1]);
  signs[1] = Sign(a.dot(b.cross(d)));
}

}  // namespace

SE3d ToolJointJacobian(const KinematicChain& chain, const double* q, int tool, FrameRt* frames,
                       double* J, int ld) {
  const RobotModel& model = chain.model();
  const int n = chain.num_joints();
  chain.Frames(q, tool, frames);
  const Eigen::Vector3d p = frames[n].t;
  for (int j = 0; j < n; ++j) JointColumn(model.joints[j], frames[j], p, J + j * ld);
  return SE3d(frames[n].R, frames[n].t);
}

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
                                     const EffectiveJoints* effective)
    : model_(&model), options_(options), effective_(effective), chain_(model) {
  CHECK(CheckModel(model).ok()) << CheckModel(model).message();
  const int n = model.num_joints();
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
  const int n = chain_.num_joints();
  FrameRt frames[kMax + 1];
  double q_eff[kMax];
  const double* x = q;
  if (effective_ != nullptr) {
    effective_->Evaluate(q, q_eff, nullptr);
    x = q_eff;
  }
  chain_.Frames(x, 0, frames);
  (void)n;
  BranchSignsOf(*model_, frames, signs);
}

IkResult InverseKinematics::Solve(const IkTarget& target, const double* seed, double* q) const {
  CHECK(target.tool >= 0 && target.tool < model_->num_tools()) << "tool index " << target.tool;
  return target.has_orientation ? SolveTask<6>(target, seed, q) : SolveTask<3>(target, seed, q);
}

template <int M>
IkResult InverseKinematics::SolveTask(const IkTarget& target, const double* seed,
                                      double* q_out) const {
  const int n = chain_.num_joints();
  double start[kMax], best_q[kMax], trial_q[kMax];
  std::copy(seed, seed + n, start);
  IkResult best = Run<M>(target, seed, seed, best_q);
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
    IkResult r = Run<M>(target, seed, start, trial_q);
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

template <int M>
IkResult InverseKinematics::Run(const IkTarget& target, const double* seed_in,
                                const double* start_in, double* q_out) const {
  using MatJ = Eigen::Matrix<double, M, Eigen::Dynamic, 0, M, kMax>;
  using VecN = Eigen::Matrix<double, Eigen::Dynamic, 1, 0, kMax, 1>;
  using VecM = Eigen::Matrix<double, M, 1>;
  using MatM = Eigen::Matrix<double, M, M>;
  const RobotModel& model = *model_;
  const IkOptions& o = options_;
  const int n = chain_.num_joints();
  const double L = o.orientation_weight;
  const bool redundant = n > M;

  VecN lower(n), upper(n), max_step(n), seed(n), q(n);
  for (int j = 0; j < n; ++j) {
    const Joint& joint = model.joints[j];
    lower(j) = o.respect_limits ? joint.lower : -HUGE_VAL;
    upper(j) = o.respect_limits ? joint.upper : HUGE_VAL;
    max_step(j) = joint.type == JointType::kRevolute ? o.max_step_revolute : o.max_step_prismatic;
    seed(j) = std::min(std::max(seed_in[j], lower(j)), upper(j));
    q(j) = std::min(std::max(start_in[j], lower(j)), upper(j));
  }

  FrameRt frames[kMax + 1];
  double J6[6 * kMax];
  double q_eff[kMax];
  double dg_dq[kMax * kMax];

  // Weighted task error and Jacobian at x; returns |e|^2.
  auto evaluate = [&](const VecN& x, VecM* e, MatJ* J) {
    const double* qe = x.data();
    if (effective_ != nullptr) {
      effective_->Evaluate(x.data(), q_eff, dg_dq);
      qe = q_eff;
    }
    ToolJointJacobian(chain_, qe, target.tool, frames, J6, 6);
    const FrameRt& T = frames[n];
    e->template head<3>() = target.position - T.t;
    const Eigen::Map<const Eigen::Matrix<double, 6, Eigen::Dynamic>> J_full(J6, 6, n);
    J->resize(M, n);
    J->template topRows<3>() = J_full.template topRows<3>();
    if constexpr (M == 6) {
      e->template tail<3>() = L * LogSO3<double>(target.rotation * T.R.transpose());
      J->template bottomRows<3>() = L * J_full.template bottomRows<3>();
    }
    if (effective_ != nullptr) {
      const Eigen::Map<const Eigen::MatrixXd> G(dg_dq, n, n);
      const MatJ Jq = *J * G;
      *J = Jq;
    }
    return e->squaredNorm();
  };
  auto task_ok = [&](const VecM& e) {
    if (e.template head<3>().norm() > o.position_tolerance) return false;
    if constexpr (M == 6) {
      if (e.template tail<3>().norm() > L * o.orientation_tolerance) return false;
    }
    return true;
  };

  VecM e;
  MatJ J(M, n);
  double merit = evaluate(q, &e, &J);
  int seed_signs[2] = {0, 0};
  const bool check_branch = o.check_branch && branch_defined_;
  if (check_branch) {
    if (start_in == seed_in) {
      BranchSignsOf(model, frames, seed_signs);
    } else {
      BranchSigns(seed.data(), seed_signs);
    }
  }

  // One damped step with the active set of limits (see the header). Returns the step in *d.
  bool limit_hit = false;  // some step of this run was cut at a joint limit
  auto compute_step = [&](double lambda2, double beta, VecN* d) {
    bool locked[kMax] = {};
    VecN fixed = VecN::Zero(n);
    for (int round = 0; round <= n; ++round) {
      MatJ Jf = J;
      VecM rhs = e;
      VecN r = beta * (seed - q);
      for (int j = 0; j < n; ++j) {
        if (!locked[j]) continue;
        rhs -= J.col(j) * fixed(j);
        Jf.col(j).setZero();
        r(j) = 0;
      }
      MatM A = Jf * Jf.transpose();
      const double trace = A.trace();
      A.diagonal().array() += lambda2 + (trace > 0 ? 1e-13 * trace / M : 1e-30);
      rhs -= Jf * r;
      const VecM y = A.llt().solve(rhs);
      *d = r + Jf.transpose() * y;
      for (int j = 0; j < n; ++j) {
        if (locked[j]) (*d)(j) = fixed(j);
      }
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
          fixed(j) = (x > upper(j) ? upper(j) : lower(j)) - q(j);
          changed = true;
          limit_hit = true;
        }
      }
      if (!changed) return;
    }
  };

  IkResult result;
  bool converged = false;
  bool evaluated_at_q = true;  // `frames` hold the configuration q
  double lambda2 = 0, beta = 1;
  VecN d(n), q_new(n);
  VecM e_new;
  MatJ J_new(M, n);
  int it = 0;
  for (; it < o.max_iterations; ++it) {
    const bool ok = task_ok(e);
    if (ok && !redundant) {
      converged = true;
      break;
    }
    compute_step(lambda2, beta, &d);
    if (ok && d.template lpNorm<Eigen::Infinity>() < o.step_tolerance) {
      converged = true;
      break;
    }
    q_new = q + d;
    for (int j = 0; j < n; ++j) q_new(j) = std::min(std::max(q_new(j), lower(j)), upper(j));
    const double merit_new = evaluate(q_new, &e_new, &J_new);
    // Near the target, a step toward the seed in the null space may raise the task error at
    // second order; the next step removes that, so such steps are accepted (kNullSpaceSlack).
    if (merit_new <= merit || merit_new <= kNullSpaceSlack * kNullSpaceSlack || task_ok(e_new)) {
      q = q_new;
      e = e_new;
      J = J_new;
      merit = merit_new;
      evaluated_at_q = true;
      lambda2 *= 0.1;
      if (lambda2 < 1e-12 * J.squaredNorm() / M) lambda2 = 0;
      beta = 1;
    } else {
      evaluated_at_q = false;
      const double scale = std::max(J.squaredNorm() / M, 1e-30);
      lambda2 = std::max(lambda2 * 10, 1e-6 * scale);
      beta *= 0.5;
      if (lambda2 > 1e12 * scale) break;  // no step reduces the error: stalled
    }
  }
  // A redundant task whose null-space pull has not settled still reached the target.
  if (!converged && task_ok(e) && redundant) converged = true;

  // Smallest singular value of the weighted task Jacobian at q.
  if (M <= n) {
    result.sigma_min = std::sqrt(SmallestEigenvalue<M>(J * J.transpose()));
  } else {
    const Eigen::MatrixXd A = J.transpose() * J;
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(A, Eigen::EigenvaluesOnly);
    result.sigma_min = std::sqrt(std::max(0.0, eig.eigenvalues()(0)));
  }
  result.position_error = e.template head<3>().norm();
  if constexpr (M == 6) result.orientation_error = e.template tail<3>().norm() / L;
  result.iterations = it;
  for (int j = 0; j < n; ++j) {
    q_out[j] = q(j);
    if (q(j) == lower(j) || q(j) == upper(j)) result.at_limit = true;
  }
  double corr2 = 0;
  for (int j = 0; j < n; ++j) corr2 += (q(j) - seed_in[j]) * (q(j) - seed_in[j]);
  result.correction = std::sqrt(corr2);
  if (check_branch) {
    if (!evaluated_at_q) evaluate(q, &e_new, &J_new);
    int signs[2];
    BranchSignsOf(model, frames, signs);
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
                    : singular      ? IkStatus::kSingular
                                    : IkStatus::kUnreachable;
  }
  return result;
}

template IkResult InverseKinematics::SolveTask<3>(const IkTarget&, const double*, double*) const;
template IkResult InverseKinematics::SolveTask<6>(const IkTarget&, const double*, double*) const;
template IkResult InverseKinematics::Run<3>(const IkTarget&, const double*, const double*,
                                            double*) const;
template IkResult InverseKinematics::Run<6>(const IkTarget&, const double*, const double*,
                                            double*) const;

}  // namespace lpoe
