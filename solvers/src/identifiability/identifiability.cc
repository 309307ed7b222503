#include "identifiability/identifiability.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <glog/logging.h>

#include "lpoe/kinematics/eigen_decompositions.h"
#include "lpoe/kinematics/householder.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "identifiability/structural_identifiability.h"

namespace lpoe {
namespace internal {

Eigen::VectorXd ColumnScale(const Eigen::MatrixXd& H) {
  // A column that is zero but for round-off (a rotation about an axis through the measured point,
  // computed in a rotated frame) is not scaled up into a direction of its own.
  const double floor =
      kRoundOffColumn * kRoundOffColumn * (H.rows() ? H.diagonal().maxCoeff() : 0.0);
  Eigen::VectorXd d(H.rows());
  for (int j = 0; j < H.rows(); ++j) d(j) = H(j, j) > floor ? 1.0 / std::sqrt(H(j, j)) : 1.0;
  return d;
}

Identifiability Analyze(const Eigen::MatrixXd& H, bool weakest) {
  const Eigen::VectorXd d = ColumnScale(H);
  const Eigen::MatrixXd Hs = d.asDiagonal() * H * d.asDiagonal();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(
      Hs, weakest ? Eigen::ComputeEigenvectors : Eigen::EigenvaluesOnly);
  Identifiability out;
  out.condition = std::numeric_limits<double>::infinity();
  const int P = static_cast<int>(H.rows());
  out.singular_values.resize(P);
  for (int k = 0; k < P; ++k) {
    out.singular_values(k) = std::sqrt(std::max(0.0, eig.eigenvalues()(P - 1 - k)));
  }
  const double smax = out.singular_values(0);
  // Numerical rank of the scaled Jacobian; sqrt(eps) relative since we work on J^T J.
  const double tol = smax * 1e-8;
  for (int k = 0; k < P; ++k) out.rank += out.singular_values(k) > tol;
  const double smin = out.singular_values(P - 1);
  out.condition = smin > 0 ? smax / smin : std::numeric_limits<double>::infinity();
  if (weakest) out.weakest = eig.eigenvectors().col(0);
  return out;
}

std::string WeakestDirections(const Parameterization& p, const Eigen::VectorXd& v) {
  std::vector<int> idx(v.size());
  for (int k = 0; k < v.size(); ++k) idx[k] = k;
  std::sort(idx.begin(), idx.end(), [&](int a, int b) { return std::abs(v(a)) > std::abs(v(b)); });
  std::ostringstream os;
  for (int k = 0; k < std::min<int>(3, static_cast<int>(idx.size())); ++k) {
    if (k) os << ", ";
    os << p.parameters[idx[k]].name;
  }
  return os.str();
}

Eigen::MatrixXd NormalMatrix(const RobotModel& model, const MeasurementSet& data,
                             const Parameterization& p, bool use_orientation,
                             double orientation_weight) {
  NormalEquationsOptions o;
  o.use_orientation = use_orientation;
  o.orientation_weight = orientation_weight;
  return NormalEquationsOf(model, data, p, Eigen::VectorXd(), o).H;
}

std::vector<Eigen::MatrixXd> JointBlockBases(const Eigen::MatrixXd& H, const Parameterization& pi,
                                             double tolerance) {
  // Columns kept so far, as combinations of pi's parameters: the identifiable frames, then each
  // block's kept combinations (basis_b on the block's rows). Kept^T X is formed from those rows,
  // and Kept^T H Kept grown block by block: no product with the whole matrix.
  const int frame_columns = pi.num_frame_parameters();
  std::vector<Eigen::MatrixXd> bases;
  auto kept_transpose_times = [&](const Eigen::MatrixXd& X) {
    int rows = frame_columns;
    for (const Eigen::MatrixXd& B : bases) rows += static_cast<int>(B.cols());
    Eigen::MatrixXd out(rows, X.cols());
    out.topRows(frame_columns) = X.topRows(frame_columns);
    int row = frame_columns;
    for (size_t b = 0; b < bases.size(); ++b) {
      const Eigen::MatrixXd& B = bases[b];
      out.middleRows(row, B.cols()).noalias() =
          B.transpose() * X.middleRows(pi.joint_blocks[b].offset, B.rows());
      row += static_cast<int>(B.cols());
    }
    return out;
  };
  Eigen::MatrixXd Hkk = H.topLeftCorner(frame_columns, frame_columns);
  for (const JointBlock& block : pi.joint_blocks) {
    const int P = block.term->num_parameters();
    const Eigen::MatrixXd Hkb = kept_transpose_times(H.middleCols(block.offset, P));
    const Eigen::MatrixXd Hbb = H.block(block.offset, block.offset, P, P);
    // Schur complement S = Hbb - Hkb^T Hkk^+ Hkb with the (column-scaled) kept block's
    // pseudo-inverse. The kept block is well conditioned by construction (identifiable frames and
    // kept combinations): then its Cholesky factor L gives the same S from Z = L^-1 Hkb; the
    // eigenproblem (the pseudo-inverse proper) only when the factorization fails or its
    // reciprocal condition estimate is below 1e-10, where eigenvalues under 1e-14 of the largest
    // might be dropped.
    const Eigen::VectorXd dk = ColumnScale(Hkk);
    const Eigen::MatrixXd Hks = dk.asDiagonal() * Hkk * dk.asDiagonal();
    const Eigen::MatrixXd Hkb_s = dk.asDiagonal() * Hkb;
    Eigen::MatrixXd S;
    const Eigen::LLT<Eigen::MatrixXd> lk(Hks);
    if (Hks.rows() > 0 && lk.info() == Eigen::Success && lk.rcond() > 1e-10) {
      const Eigen::MatrixXd Z = lk.matrixL().solve(Hkb_s);
      S = Hbb;
      S.noalias() -= Z.transpose() * Z;
    } else {
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> ek(Hks);
      const double kmax = ek.eigenvalues().size() > 0 ? ek.eigenvalues().maxCoeff() : 0.0;
      Eigen::VectorXd inv = ek.eigenvalues();
      for (int k = 0; k < inv.size(); ++k) inv(k) = inv(k) > 1e-14 * kmax ? 1.0 / inv(k) : 0.0;
      const Eigen::MatrixXd W = ek.eigenvectors().transpose() * Hkb_s;
      S = Hbb - W.transpose() * inv.asDiagonal() * W;
    }
    const Eigen::VectorXd db = ColumnScale(Hbb);
    // Parameters that move nothing at these rows (a zero column, e.g. the gravity torque about a
    // vertical axis) have a zero row and column in S: they are left out of the eigenproblem, whose
    // cost grows with the cube of its size, and can only be left out of the basis.
    std::vector<int> live;
    for (int k = 0; k < P; ++k) {
      if (Hbb(k, k) != 0) live.push_back(k);
    }
    const int L = static_cast<int>(live.size());
    Eigen::MatrixXd Ss(L, L);
    for (int a = 0; a < L; ++a) {
      for (int c = 0; c < L; ++c) Ss(a, c) = db(live[a]) * S(live[a], live[c]) * db(live[c]);
    }
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(Ss);
    std::vector<int> keep;
    for (int k = 0; k < L; ++k) {
      if (std::sqrt(std::max(0.0, es.eigenvalues()(k))) > tolerance) keep.push_back(k);
    }
    Eigen::MatrixXd basis;
    if (static_cast<int>(keep.size()) == P) {
      basis = Eigen::MatrixXd::Identity(P, P);  // every parameter: keep their own names
    } else {
      Eigen::MatrixXd V = Eigen::MatrixXd::Zero(P, keep.size());
      // Scaled coordinates z = theta / db: theta = db * z.
      for (size_t k = 0; k < keep.size(); ++k) {
        for (int a = 0; a < L; ++a) V(live[a], k) = db(live[a]) * es.eigenvectors()(a, keep[k]);
      }
      basis = HouseholderQColumns(Eigen::HouseholderQR<Eigen::MatrixXd>(V), 0, V.cols());
    }
    bases.push_back(basis);
    if (bases.size() == pi.joint_blocks.size()) break;  // no later block reads it
    // Kept^T H Kept with the new block's combinations.
    const Eigen::MatrixXd cross = Hkb * basis;
    const int k0 = static_cast<int>(Hkk.rows()), kb = static_cast<int>(basis.cols());
    Eigen::MatrixXd grown(k0 + kb, k0 + kb);
    grown.topLeftCorner(k0, k0) = Hkk;
    grown.topRightCorner(k0, kb) = cross;
    grown.bottomLeftCorner(kb, k0) = cross.transpose();
    grown.bottomRightCorner(kb, kb) = basis.transpose() * Hbb * basis;
    Hkk = std::move(grown);
  }
  return bases;
}

Parameterization SolverParameterization(const RobotModel& nominal, const MeasurementSet& data,
                                        const SolverParameterizationRequest& request) {
  const ParameterizationKind kind = request.kind;
  const bool use_orientation = request.use_orientation;
  const double orientation_weight = request.orientation_weight;
  const std::vector<std::shared_ptr<const JointTerm>>& terms = request.terms;
  const double tolerance = request.tolerance;
  const RobotModel* structure_reference = request.structure_reference;
  NormalEquations* analysed = request.analysed;
  JointSpaceRegressors* regressors = request.regressors;
  Parameterization* analysed_parameterization = request.analysed_parameterization;
  const DataKind data_kind = TrackerDataKind(TrackerKindId(use_orientation));
  Parameterization p = MakeParameterization(nominal, kind, data_kind);
  // The structural check (a Jacobian at generic configurations and its Gram-Schmidt) once for both
  // parameterizations below: its result depends on the chain, the data's tools and the data kind.
  const std::vector<Direction> lost =
      StructurallyUnidentifiable(structure_reference ? *structure_reference : nominal, data,
                                 use_orientation, orientation_weight);
  LeaveOutDirections(lost, &p);
  if (terms.empty()) return p;
  // The analysis runs on the identifiable frames (the full ones are singular by construction) with
  // every joint block whole: p itself when it is the identifiable one.
  Parameterization pi;
  if (kind == ParameterizationKind::kIdentifiable) {
    pi = p;
  } else {
    pi = MakeParameterization(nominal, ParameterizationKind::kIdentifiable, data_kind);
    LeaveOutDirections(lost, &pi);
  }
  for (const auto& term : terms) {
    CHECK_EQ(term->num_joints(), nominal.num_joints()) << term->name();
    AddJointBlock(term, &pi);
  }
  if (analysed_parameterization) *analysed_parameterization = pi;
  // The analysis' normal equations by the joint blocks' structure (normal_equations.h), kept for
  // the caller: they are the first linearization at `nominal` of any reduction of these blocks.
  JointSpaceRegressors local_regs;
  JointSpaceRegressors& regs = regressors ? *regressors : local_regs;
  regs = BuildJointSpaceRegressors(pi, data);
  NormalEquationsOptions o;
  o.use_orientation = use_orientation;
  o.orientation_weight = orientation_weight;
  o.joint.regressors = &regs;
  NormalEquations local_ne;
  NormalEquations& ne = analysed ? *analysed : local_ne;
  ne = NormalEquationsOf(nominal, data, pi, Eigen::VectorXd(), o);
  const std::vector<Eigen::MatrixXd> bases = JointBlockBases(ne.H, pi, tolerance);
  for (const auto& term : terms) AddJointBlock(term, &p);
  for (size_t b = 0; b < bases.size(); ++b) {
    SetJointBlockBasis(static_cast<int>(b), bases[b],
                       "not separable from the geometry or from the earlier joint-space terms "
                       "with these data",
                       &p);
  }
  return p;
}

std::string TooFewEquationsMessage(int rows, long equations, int identifiable, int per_row) {
  std::ostringstream os;
  os << rows << " measurements give " << equations << " equations, fewer than the "
     << identifiable << " identifiable parameters; at least "
     << (identifiable + per_row - 1) / per_row
     << " configurations are needed (several times that for a reliable calibration)";
  return os.str();
}

std::string NotIdentifiableMessage(const Identifiability& id, int identifiable,
                                   double max_condition_number, const Parameterization& p) {
  std::ostringstream os;
  os << "the data cannot identify the model: the column-scaled Jacobian has rank " << id.rank
     << " of " << identifiable << " and condition number " << id.condition << " (limit "
     << max_condition_number << "); weakest directions: " << WeakestDirections(p, id.weakest)
     << ". The poses are too few or too similar: measure configurations that move every joint";
  return os.str();
}

}  // namespace internal
}  // namespace lpoe
