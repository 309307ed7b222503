#include "calibration/prior_terms.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Cholesky>
#include <glog/logging.h>

#include "lpoe/kinematics/eigen_decompositions.h"

namespace lpoe {
namespace internal {
namespace {

// Upper factor L of a positive semi-definite information matrix M = L^T L (through its
// eigendecomposition, so that a zero eigenvalue, "no prior in that direction", is allowed).
Eigen::MatrixXd SqrtInformation(const Eigen::MatrixXd& M) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(0.5 * (M + M.transpose()));
  const Eigen::VectorXd l = eig.eigenvalues().cwiseMax(0.0).cwiseSqrt();
  return l.asDiagonal() * eig.eigenvectors().transpose();
}

// Rows of `data` the joint terms' default scales are evaluated on (at most 256, evenly spread).
std::vector<int> SampleRows(const MeasurementSet& data) {
  std::vector<int> rows;
  const int n = data.size();
  const int every = std::max(1, n / 256);
  for (int r = 0; r < n; r += every) rows.push_back(r);
  return rows;
}

}  // namespace

ResolvedPrior ResolvePrior(const ParameterPrior& prior, const RobotModel& start,
                           const MeasurementSet& data, const Parameterization& p) {
  ResolvedPrior out;
  out.active = true;
  out.reference = prior.reference ? *prior.reference : start;
  CHECK_EQ(out.reference.num_frames(), start.num_frames()) << "prior reference of another chain";
  out.data_sigma = prior.data_sigma_mm;
  out.informative = prior.informative;
  for (int f = 0; f < start.num_frames(); ++f) {
    out.frame_sqrt.push_back(SqrtInformation(FrameInformation(prior, start, f)));
  }
  const std::vector<int> rows = SampleRows(data);
  for (const JointBlock& b : p.joint_blocks) {
    const int P = b.term->num_parameters();
    const int n = b.term->num_joints();
    const JointTermPrior* given = nullptr;
    for (const JointTermPrior& t : prior.joint_terms) {
      if (t.name == b.term->name()) given = &t;
    }
    Eigen::VectorXd reference = Eigen::VectorXd::Zero(P);
    if (given != nullptr && given->reference.size() == P) reference = given->reference;
    Eigen::MatrixXd information;
    if (given != nullptr && given->information.rows() == P && given->information.cols() == P) {
      information = given->information / (prior.scale * prior.scale);
    } else {
      // Each parameter's standard deviation: the joint-space effect scales.joint_term_mrad over
      // the RMS of its regressor column on the rows.
      Eigen::VectorXd mean_square = Eigen::VectorXd::Zero(P);
      Eigen::MatrixXd Y(n, P);
      for (int r : rows) {
        b.term->Regressor(data.q(r), Y.data());
        mean_square += Y.colwise().squaredNorm().transpose();
      }
      mean_square /= std::max<size_t>(1, rows.size());
      const double sigma_q = 1e-3 * prior.scales.joint_term_mrad * prior.scale;
      information = (mean_square / (sigma_q * sigma_q)).asDiagonal();
    }
    out.term_reference.push_back(reference);
    out.term_sqrt.push_back(SqrtInformation(information));
  }
  return out;
}

PriorRows LinearizePrior(const ResolvedPrior& prior, const Parameterization& p,
                         const RobotModel& model, const Eigen::VectorXd& joint_state) {
  PriorRows out;
  const int n = model.num_joints();
  int rows = 0;
  for (size_t f = 0; f < p.basis.size(); ++f) rows += p.basis[f].cols() > 0 ? 6 : 0;
  for (const JointBlock& b : p.joint_blocks) rows += b.basis.cols() > 0 ? b.basis.rows() : 0;
  out.A = Eigen::MatrixXd::Zero(rows, p.num_parameters);
  out.r = Eigen::VectorXd::Zero(rows);
  int row = 0;
  constexpr double h = 1e-6;  // central differences of the log: relative error ~1e-10
  for (size_t f = 0; f < p.basis.size(); ++f) {
    const Eigen::MatrixXd& B = p.basis[f];
    if (B.cols() == 0) continue;
    const SE3d& T = static_cast<int>(f) < n ? model.joints[f].origin : model.tools[f - n].origin;
    const SE3d& R =
        static_cast<int>(f) < n ? prior.reference.joints[f].origin : prior.reference.tools[f - n].origin;
    const SE3d Rinv = R.Inverse();
    const Matrix6d& L = prior.frame_sqrt[f];
    out.r.segment<6>(row) = L * LogSE3(Rinv * T);
    for (int c = 0; c < B.cols(); ++c) {
      const Vector6d d = h * B.col(c);
      const Vector6d plus = LogSE3(Rinv * (T * ExpSE3(d)));
      const Vector6d minus = LogSE3(Rinv * (T * ExpSE3(Vector6d(-d))));
      out.A.block<6, 1>(row, p.offset[f] + c) = L * (plus - minus) / (2 * h);
    }
    row += 6;
  }
  const int frame_columns = p.num_frame_parameters();
  for (size_t b = 0; b < p.joint_blocks.size(); ++b) {
    const JointBlock& jb = p.joint_blocks[b];
    const int k = static_cast<int>(jb.basis.cols());
    if (k == 0) continue;
    const int P = static_cast<int>(jb.basis.rows());
    const Eigen::VectorXd theta = jb.basis * joint_state.segment(jb.offset - frame_columns, k);
    out.r.segment(row, P) = prior.term_sqrt[b] * (theta - prior.term_reference[b]);
    out.A.block(row, jb.offset, P, k) = prior.term_sqrt[b] * jb.basis;
    row += P;
  }
  return out;
}

void AddPrior(const PriorRows& rows, double s2, Eigen::MatrixXd* H, Eigen::VectorXd* g) {
  if (rows.r.size() == 0) return;
  H->noalias() += s2 * rows.A.transpose() * rows.A;
  if (g != nullptr) g->noalias() -= s2 * rows.A.transpose() * rows.r;
}

double PriorDataVariance(const ResolvedPrior& prior, double data_cost, long dof) {
  if (prior.data_sigma > 0) return prior.data_sigma * prior.data_sigma;
  // No redundancy (dof <= 0): the rows fit exactly whatever the prior and estimate no s; the prior
  // is then weighed with nothing (the pipeline refuses such data unless the prior is informative,
  // which then carries its own s).
  const double s2 = dof > 0 ? 2.0 * data_cost / static_cast<double>(dof) : 0.0;
  return std::max(s2, 1e-24);
}

double PriorStepDataVariance(const ResolvedPrior& prior, const Eigen::MatrixXd& H,
                             const Eigen::VectorXd& g, double cost, const PriorRows& rows,
                             long dof) {
  double s2 = PriorDataVariance(prior, cost, dof);
  if (prior.data_sigma > 0 || rows.r.size() == 0) return s2;
  const Eigen::MatrixXd Hp = rows.A.transpose() * rows.A;
  const Eigen::VectorXd gp = rows.A.transpose() * rows.r;
  constexpr int kRounds = 30;
  for (int k = 0; k < kRounds; ++k) {
    const Eigen::MatrixXd M = H + s2 * Hp;
    const Eigen::VectorXd d = M.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
    const Eigen::LLT<Eigen::MatrixXd> llt(d.asDiagonal() * M * d.asDiagonal());
    if (llt.info() != Eigen::Success) break;
    const Eigen::VectorXd x = d.asDiagonal() * llt.solve(d.asDiagonal() * (g - s2 * gp));
    const double c = std::max(0.0, cost - g.dot(x) + 0.5 * x.dot(H * x));
    const double next = PriorDataVariance(prior, c, dof);
    const bool settled = std::abs(next - s2) <= 1e-12 * s2;
    s2 = next;
    if (settled) break;
  }
  return s2;
}

void PriorContribution(const PriorRows& rows, const Eigen::MatrixXd& H_data, double s2,
                       Eigen::VectorXd* prior_sd, Eigen::VectorXd* data_share) {
  const int P = static_cast<int>(H_data.rows());
  *prior_sd = Eigen::VectorXd::Constant(P, std::numeric_limits<double>::infinity());
  *data_share = Eigen::VectorXd::Ones(P);
  if (rows.r.size() == 0 || rows.A.cols() != P) return;
  const Eigen::MatrixXd Hp = rows.A.transpose() * rows.A;  // prior information, x units
  // The prior's variance of each parameter with a prior row: the inverse of its information on
  // the parameters that have one (the blocks are separate: frames, joint blocks).
  std::vector<int> with;
  for (int i = 0; i < P; ++i) {
    if (Hp(i, i) > 0) with.push_back(i);
  }
  if (with.empty()) return;
  const int m = static_cast<int>(with.size());
  Eigen::MatrixXd Hw(m, m);
  for (int a = 0; a < m; ++a) {
    for (int b = 0; b < m; ++b) Hw(a, b) = Hp(with[a], with[b]);
  }
  const Eigen::MatrixXd Cp = Hw.ldlt().solve(Eigen::MatrixXd::Identity(m, m));
  // The posterior in x units: (H_data / s2 + Hp)^-1.
  const Eigen::MatrixXd Hpost = H_data / s2 + Hp;
  const Eigen::VectorXd d = Hpost.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  const Eigen::MatrixXd Hs = d.asDiagonal() * Hpost * d.asDiagonal();
  const Eigen::MatrixXd Cs = Hs.ldlt().solve(Eigen::MatrixXd::Identity(P, P));
  for (int a = 0; a < m; ++a) {
    const int i = with[a];
    const double prior_var = Cp(a, a);
    const double post_var = Cs(i, i) * d(i) * d(i);
    (*prior_sd)(i) = std::sqrt(std::max(prior_var, 0.0));
    (*data_share)(i) = prior_var > 0 ? std::clamp(1.0 - post_var / prior_var, 0.0, 1.0) : 1.0;
  }
}

}  // namespace internal
}  // namespace lpoe
