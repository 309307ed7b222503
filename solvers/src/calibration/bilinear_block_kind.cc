// The kinds of effects bilinear with a joint-space term (block_kind.h, BilinearBlockKind): their
// blocks, columns and identifiability arithmetic from the effect alone.
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <Eigen/Eigenvalues>
#include <glog/logging.h>

#include "calibration/block_kind.h"
#include "calibration/problem_setup.h"
#include "identifiability/identifiability.h"
#include "linearization/normal_equations.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"

namespace lpoe {
namespace internal {
namespace {

// The joint block of p that is `effect`'s partner; -1 when there is none.
int PartnerBlock(const Parameterization& p, const BilinearJointEffect& effect) {
  for (size_t b = 0; b < p.joint_blocks.size(); ++b) {
    if (p.joint_blocks[b].term->name() == effect.partner()) return static_cast<int>(b);
  }
  return -1;
}

}  // namespace

bool BilinearBlockKind::Requested(const ProblemDefinitionOptions& options) const {
  for (const auto& e : options.bilinear_effects) {
    if (e && std::string(e->name()) == name()) return true;
  }
  return false;
}

bool BilinearBlockKind::In(const Parameterization& p) const {
  for (const BilinearBlock& b : p.bilinear_blocks) {
    if (std::string(b.effect->name()) == name()) return true;
  }
  return false;
}

Status BilinearBlockKind::Add(const ProblemDefinitionOptions& options, Parameterization* p) const {
  for (const auto& effect : options.bilinear_effects) {
    if (!effect || std::string(effect->name()) != name()) continue;
    const int b = PartnerBlock(*p, *effect);
    if (b < 0) return Status::Error(needs_partner_message());
    if (p->joint_blocks[b].basis.cols() == 0) {
      return Status::Error(std::string("the ") + description() + " needs identified " +
                           effect->partner() + " combinations; these data identify none");
    }
    AddBilinearBlock(effect, b, p);
  }
  return Status::Ok();
}

void BilinearBlockKind::AppendBlocks(const ProblemSetup& setup, const RobotModel& /*nominal*/,
                                     std::vector<ProblemBlock>* out) const {
  const Parameterization& p = setup.all;
  const int F = p.num_frame_parameters();
  for (size_t i = 0; i < p.bilinear_blocks.size(); ++i) {
    const BilinearBlock& block = p.bilinear_blocks[i];
    if (std::string(block.effect->name()) != name()) continue;
    ProblemBlock b;
    b.kind = this;
    b.index = static_cast<int>(i);
    b.offset = block.offset;
    b.tangent_size = block.effect->num_parameters();
    for (int c = 0; c < b.tangent_size; ++c) {
      b.values.push_back(setup.initial_joint_state(block.offset - F + c));
    }
    b.initial = b.values;
    out->push_back(std::move(b));
  }
}

void BilinearBlockKind::Columns(const BlockColumnsContext& ctx, const ProblemBlock& block,
                                const MeasurementSet& data, int r, Eigen::MatrixXd* J) const {
  RowLinearization row;
  LinearizeRow(ctx, data, r, &row);
  *J = row.J_q *
       row.R.middleCols(block.offset - ctx.p->num_frame_parameters(), block.tangent_size);
}

void AddNonlinearRowColumns(const Parameterization& p, const double* q,
                            const Eigen::VectorXd& joint_state, Eigen::Ref<Eigen::MatrixXd> R,
                            Eigen::VectorXd* q_eff) {
  if (p.bilinear_blocks.empty()) return;
  const int F = p.num_frame_parameters();
  // Per-thread scratch: called for every row of every linearization.
  struct Scratch {
    Eigen::VectorXd x, t, ddq;
    std::vector<Eigen::MatrixXd> Z;
    Eigen::MatrixXd dR, D;
  };
  thread_local Scratch s;
  for (const BilinearBlock& block : p.bilinear_blocks) {
    const JointBlock& partner = p.joint_blocks[block.partner];
    const int k = static_cast<int>(partner.basis.cols());
    const int m = block.effect->num_parameters();
    const int c0 = partner.offset - F;  // the partner's first column in R
    const int t0 = block.offset - F;    // the block's first column
    s.x.setZero(k);
    s.t.setZero(m);
    if (joint_state.size() > 0) {
      s.x = joint_state.segment(c0, k);
      s.t = joint_state.segment(t0, m);
    }
    block.effect->RowRegressors(partner.basis, q, &s.Z);
    BilinearJointColumns(*block.effect, s.t.data(), s.Z, s.x.data(), &s.ddq, &s.dR, &s.D);
    R.middleCols(c0, k) += s.dR;
    R.middleCols(t0, m) = s.D;
    *q_eff += s.ddq;
  }
}

std::shared_ptr<const BilinearRow> BilinearRowOf(const Parameterization& p, int b, const double* q,
                                                 int partner_block) {
  const BilinearBlock& block = p.bilinear_blocks[b];
  auto row = std::make_shared<BilinearRow>();
  row->block = partner_block;
  row->effect = block.effect;
  block.effect->RowRegressors(p.joint_blocks[block.partner].basis, q, &row->Z);
  return row;
}

Status CheckBlockKindPartners(const std::vector<std::shared_ptr<const JointTerm>>& terms,
                              const ProblemDefinitionOptions& options) {
  for (size_t i = 0; i < options.bilinear_effects.size(); ++i) {
    const auto& effect = options.bilinear_effects[i];
    if (effect == nullptr) return Status::Error("a bilinear effect is null");
    for (size_t j = 0; j < i; ++j) {
      if (options.bilinear_effects[j] &&
          std::string(options.bilinear_effects[j]->name()) == effect->name()) {
        return Status::Error(std::string("the bilinear effect '") + effect->name() +
                             "' is given twice");
      }
    }
    const BilinearBlockKind* kind = FindBilinearBlockKind(effect->name());
    if (kind == nullptr) {
      return Status::Error(std::string("no block kind for the bilinear effect '") +
                           effect->name() + "'");
    }
    bool found = false;
    for (const auto& term : terms) found = found || (term && term->name() == effect->partner());
    if (!found) return Status::Error(kind->needs_partner_message());
  }
  return Status::Ok();
}

Status BilinearInformation(std::shared_ptr<const BilinearJointEffect> effect,
                           const MeasurementSet& data, const CalibrationResult& r0,
                           bool use_orientation, double orientation_weight, double* kept_fraction,
                           Eigen::MatrixXd* covariance) {
  *kept_fraction = 0;
  covariance->resize(0, 0);
  Parameterization p = r0.parameterization;
  LeaveOutUnmeasuredTools(r0.model, data, &p);
  const int b = PartnerBlock(p, *effect);
  if (b < 0) return Status::Error(std::string("no ") + effect->partner() + " term");
  if (p.joint_blocks[b].basis.cols() == 0) {
    return Status::Error(std::string("no identified ") + effect->partner() + " combination");
  }
  AddBilinearBlock(effect, b, &p);
  const Eigen::VectorXd state = InitialJointState(p, r0.joint_terms);
  NormalEquationsOptions rows;
  rows.use_orientation = use_orientation;
  rows.orientation_weight = orientation_weight;
  const NormalEquations lin = NormalEquationsOf(r0.model, data, p, state, rows);
  if (!lin.finite) return Status::Error("non-finite normal equations");
  const int P = p.num_parameters;
  const int m = effect->num_parameters();
  const int o = P - m;  // the block is last
  // Column scaling; a zero column (nothing moves) keeps scale 0.
  Eigen::VectorXd d(P);
  for (int k = 0; k < P; ++k) d(k) = lin.H(k, k) > 0 ? 1.0 / std::sqrt(lin.H(k, k)) : 0.0;
  if ((d.tail(m).array() == 0).any()) {
    return Status::Error(std::string("the ") + effect->name() + " moves no measured point");
  }
  const Eigen::MatrixXd Hs = d.asDiagonal() * lin.H * d.asDiagonal();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(Hs.topLeftCorner(o, o));
  const Eigen::VectorXd& l = eig.eigenvalues();
  const double largest = l.size() > 0 ? l.maxCoeff() : 0.0;
  Eigen::VectorXd inv = Eigen::VectorXd::Zero(l.size());
  for (int k = 0; k < l.size(); ++k) {
    if (l(k) > 1e-12 * largest) inv(k) = 1.0 / l(k);
  }
  const Eigen::MatrixXd B = eig.eigenvectors().transpose() * Hs.topRightCorner(o, m);
  const Eigen::MatrixXd M = Hs.bottomRightCorner(m, m) - B.transpose() * inv.asDiagonal() * B;
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> m_eig(M);
  const double smallest = m_eig.eigenvalues()(0);
  *kept_fraction = std::sqrt(std::max(0.0, smallest));
  if (smallest > 0) {
    const int per_row = TrackerResiduals(TrackerKindId(use_orientation));
    const long dof = static_cast<long>(per_row) * data.size() - P;
    const double s2 = dof > 0 ? 2.0 * lin.cost / static_cast<double>(dof) : 0.0;
    *covariance = s2 * (d.tail(m).asDiagonal() * M.inverse() * d.tail(m).asDiagonal());
  }
  return Status::Ok();
}

}  // namespace internal
}  // namespace lpoe
