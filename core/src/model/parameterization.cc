#include "lpoe/model/parameterization.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <glog/logging.h>

#include "lpoe/kinematics/eigen_decompositions.h"
#include "lpoe/kinematics/householder.h"
#include "lpoe/terms/joint_errors.h"

namespace lpoe {
namespace {

constexpr double kNullTolerance = 1e-9;
const char* const kAxisNames[6] = {"rx", "ry", "rz", "tx", "ty", "tz"};

// An orthonormal basis of span(P), where P is an orthogonal projector of rank `rank`, built from the
// canonical directions it keeps best, so that for axis-aligned twists the basis vectors are the
// canonical (omega, v) directions themselves and carry readable names.
Eigen::MatrixXd CanonicalBasis(const Matrix6d& P, int rank) {
  std::vector<int> order(6);
  std::iota(order.begin(), order.end(), 0);
  std::stable_sort(order.begin(), order.end(),
                   [&](int a, int b) { return P(a, a) > P(b, b) + 1e-12; });
  Eigen::MatrixXd B(6, rank);
  int k = 0;
  for (int idx : order) {
    if (k == rank) break;
    Vector6d v = P.col(idx);
    for (int j = 0; j < k; ++j) v -= B.col(j).dot(v) * B.col(j);
    const double norm = v.norm();
    if (norm < 1e-6) continue;
    B.col(k++) = v / norm;
  }
  CHECK_EQ(k, rank) << "could not build a basis of the projector";
  return B;
}

std::string DirectionName(const Vector6d& v) {
  int best = 0;
  v.cwiseAbs().maxCoeff(&best);
  std::string name = kAxisNames[best];
  if (std::abs(v(best)) < 1.0 - 1e-9) name += "~";  // not axis-aligned: dominant component only
  return name;
}

std::string FrameName(const RobotModel& model, int frame) {
  return frame < model.num_joints() ? model.joints[frame].name
                                    : model.tools[frame - model.num_joints()].name;
}

}  // namespace

const char* const kFixedToolReason =
    "a fixed tool (a known SMR nest: fixed: true, --fixed_tools): held as given, not calibrated";

const char* ParameterizationName(ParameterizationKind kind) {
  return kind == ParameterizationKind::kIdentifiable ? "identifiable" : "full";
}

bool ParseParameterization(const std::string& text, ParameterizationKind* kind) {
  if (text == "identifiable") {
    *kind = ParameterizationKind::kIdentifiable;
    return true;
  }
  if (text == "full") {
    *kind = ParameterizationKind::kFull;
    return true;
  }
  return false;
}

Eigen::MatrixXd TwistCentralizer(const Vector6d& twist) {
  const Matrix6d ad = LieBracketMatrix(twist);
  Eigen::JacobiSVD<Matrix6d> svd(ad, Eigen::ComputeFullV);
  const double scale = std::max(1.0, svd.singularValues()(0));
  int rank = 0;
  for (int k = 0; k < 6; ++k) rank += svd.singularValues()(k) > kNullTolerance * scale;
  const Eigen::MatrixXd N = svd.matrixV().rightCols(6 - rank);
  return CanonicalBasis(N * N.transpose(), 6 - rank);
}

Eigen::MatrixXd IdentifiableJointBasis(const Vector6d& twist) {
  const Eigen::MatrixXd N = TwistCentralizer(twist);
  const Matrix6d P = Matrix6d::Identity() - N * N.transpose();
  return CanonicalBasis(P, 6 - static_cast<int>(N.cols()));
}

Parameterization MakeParameterization(const RobotModel& model, ParameterizationKind kind,
                                      DataKind data) {
  Parameterization p;
  p.kind = kind;
  p.data = data;
  const int n = model.num_joints();
  // With a fixed tool (a known SMR nest) nothing after the last joint can absorb a perturbation of
  // its frame that commutes with its motion: the last joint's zero and its translation along the
  // axis are calibrated directions. Whether data see them (a fixed tool measured, off the axis) is
  // the structural decision's (solvers/src/identifiability/structural_identifiability.h).
  const bool fixed_tools = model.HasFixedTool();
  for (int f = 0; f < model.num_frames(); ++f) {
    Eigen::MatrixXd lost;  // 6 x k directions data cannot see
    std::string reason;
    if (f == n - 1 && fixed_tools) {
      lost = Eigen::MatrixXd::Zero(6, 0);
    } else if (f < n) {
      lost = TwistCentralizer(model.joints[f].twist);
      reason = model.joints[f].type == JointType::kRevolute
                   ? "commutes with the joint's rotation (about or along its own axis): absorbed "
                     "by the next frame"
                   : "commutes with the joint's translation (its rotation about the sliding axis "
                     "and any translation): absorbed by the next frame";
    } else if (data == DataKind::kPosition) {
      lost = Eigen::MatrixXd::Zero(6, 3);
      lost.topRows<3>().setIdentity();
      reason = "the orientation of a measured point is not observed by position data";
    } else {
      lost = Eigen::MatrixXd::Zero(6, 0);
    }
    for (int c = 0; c < lost.cols(); ++c) {
      Direction d;
      d.frame = f;
      d.vector = lost.col(c);
      d.name = FrameName(model, f) + "." + DirectionName(d.vector);
      d.reason = reason;
      p.unidentifiable.push_back(d);
    }
    if (f >= n && model.tools[f - n].fixed) {
      // Held as given, in both parameterizations: no columns (the linear solver leaves them out,
      // the Ceres problem holds the block constant). Listed with what else holds them.
      const Eigen::MatrixXd all = Eigen::MatrixXd::Identity(6, 6);
      const Eigen::MatrixXd held = data == DataKind::kPosition ? all.rightCols(3) : all;
      for (int c = 0; c < held.cols(); ++c) {
        Direction d;
        d.frame = f;
        d.vector = held.col(c);
        d.name = FrameName(model, f) + "." + DirectionName(d.vector);
        d.reason = kFixedToolReason;
        p.unidentifiable.push_back(d);
      }
      p.offset.push_back(p.num_parameters);
      p.basis.push_back(Eigen::MatrixXd::Zero(6, 0));
      continue;
    }
    Eigen::MatrixXd basis;
    if (kind == ParameterizationKind::kFull) {
      basis = Eigen::MatrixXd::Identity(6, 6);
    } else {
      const Matrix6d P = Matrix6d::Identity() - lost * lost.transpose();
      basis = CanonicalBasis(P, 6 - static_cast<int>(lost.cols()));
    }
    p.offset.push_back(p.num_parameters);
    p.num_parameters += static_cast<int>(basis.cols());
    for (int c = 0; c < basis.cols(); ++c) {
      Direction d;
      d.frame = f;
      d.vector = basis.col(c);
      d.name = FrameName(model, f) + "." + DirectionName(d.vector);
      p.parameters.push_back(d);
    }
    p.basis.push_back(std::move(basis));
  }
  return p;
}

namespace {

// A combination of joint block b's parameters, named after its dominant parameter ("~": a mixture).
Direction JointDirection(const Parameterization& p, int b, const Eigen::VectorXd& combination) {
  const JointTerm& term = *p.joint_blocks[b].term;
  Direction d;
  d.frame = -1;
  d.joint_block = b;
  d.combination = combination;
  int best = 0;
  combination.cwiseAbs().maxCoeff(&best);
  d.name = term.name() + "." + term.ParameterName(best);
  if (std::abs(combination(best)) < 1.0 - 1e-9) d.name += "~";
  return d;
}

// Whether `old`, from block.offset on, holds JointDirection's entries for block b as it is now
// (term and basis unchanged since they were made).
bool BlockDirectionsCurrent(const std::vector<Direction>& old, int frame_parameters, int b,
                            const JointBlock& block) {
  const Eigen::Index k = block.basis.cols();
  if (block.offset < frame_parameters || block.offset + k > static_cast<Eigen::Index>(old.size())) {
    return false;
  }
  const std::string prefix = block.term->name() + ".";
  for (Eigen::Index c = 0; c < k; ++c) {
    const Direction& d = old[block.offset + c];
    if (d.frame != -1 || d.joint_block != b || !d.reason.empty() ||
        d.combination.size() != block.basis.rows() || d.combination != block.basis.col(c) ||
        d.name.compare(0, prefix.size(), prefix) != 0) {
      return false;
    }
  }
  return true;
}

// Two combinations of block b may share a dominant parameter (a kept one and a left-out one, or two
// left out): the second and later get "#2", "#3", ..., kept ones first, so that each name in the
// report's lists and correlation pairs stands for one combination. Idempotent (an earlier suffix is
// dropped first).
void DistinguishNames(int b, int offset, Parameterization* p) {
  std::map<std::string, int> seen;
  auto distinguish = [&seen](Direction* d) {
    const size_t hash = d->name.rfind('#');
    if (hash != std::string::npos) d->name.erase(hash);
    const int n = ++seen[d->name];
    if (n > 1) d->name += "#" + std::to_string(n);
  };
  const int k = static_cast<int>(p->joint_blocks[b].basis.cols());
  for (int c = 0; c < k; ++c) distinguish(&p->parameters[offset + c]);
  for (Direction& d : p->unidentifiable) {
    if (d.joint_block == b) distinguish(&d);
  }
}

// Names and offsets of every joint block from the bases (blocks follow the frames). Blocks before
// `first_changed` whose entries are still current (BlockDirectionsCurrent) keep them: naming a
// combination (JointDirection) is most of the cost of adding a block or setting its basis, which
// renumber every block.
void RenumberJointBlocks(Parameterization* p, size_t first_changed = 0) {
  int frame_parameters = 0;
  for (const Eigen::MatrixXd& B : p->basis) frame_parameters += static_cast<int>(B.cols());
  std::vector<Direction> old = std::move(p->parameters);
  p->parameters.clear();
  const size_t frames_kept = std::min(old.size(), static_cast<size_t>(frame_parameters));
  p->parameters.reserve(old.size());
  for (size_t k = 0; k < frames_kept; ++k) p->parameters.push_back(std::move(old[k]));
  p->parameters.resize(frame_parameters);
  p->num_parameters = frame_parameters;
  for (size_t b = 0; b < p->joint_blocks.size(); ++b) {
    JointBlock& block = p->joint_blocks[b];
    const bool keep = b < first_changed &&
                      BlockDirectionsCurrent(old, frame_parameters, static_cast<int>(b), block);
    const int old_offset = block.offset;
    block.offset = p->num_parameters;
    p->num_parameters += static_cast<int>(block.basis.cols());
    for (int c = 0; c < block.basis.cols(); ++c) {
      if (keep) {
        p->parameters.push_back(std::move(old[old_offset + c]));
      } else {
        p->parameters.push_back(JointDirection(*p, static_cast<int>(b), block.basis.col(c)));
      }
    }
    if (!keep) DistinguishNames(static_cast<int>(b), block.offset, p);
  }
  for (BilinearBlock& block : p->bilinear_blocks) {
    block.offset = p->num_parameters;
    p->num_parameters += block.effect->num_parameters();
    for (int a = 0; a < block.effect->num_parameters(); ++a) {
      Direction d;
      d.frame = -1;
      d.joint_block = -1;
      d.name = block.effect->parameter_name(a);
      p->parameters.push_back(d);
    }
  }
}

}  // namespace

void AddJointBlock(std::shared_ptr<const JointTerm> term, Parameterization* p) {
  CHECK(term != nullptr);
  JointBlock block;
  block.basis = Eigen::MatrixXd::Identity(term->num_parameters(), term->num_parameters());
  block.term = std::move(term);
  p->joint_blocks.push_back(std::move(block));
  RenumberJointBlocks(p, p->joint_blocks.size() - 1);
}

void SetJointBlockBasis(int b, const Eigen::MatrixXd& basis, const std::string& reason,
                        Parameterization* p) {
  JointBlock& block = p->joint_blocks[b];
  const int P = block.term->num_parameters();
  CHECK_EQ(basis.rows(), P);
  // The left-out combinations: an orthonormal basis of the kept ones' complement, the last P - k
  // columns of the Householder Q of the (orthonormal) basis (none when every parameter is kept).
  const int k = static_cast<int>(basis.cols());
  if (k < P) {
    const Eigen::MatrixXd C =
        k == 0 ? Eigen::MatrixXd::Identity(P, P)
               : HouseholderQColumns(Eigen::HouseholderQR<Eigen::MatrixXd>(basis), k, P - k);
    for (int c = 0; c < P - k; ++c) {
      Direction d = JointDirection(*p, b, C.col(c));
      d.reason = reason;
      p->unidentifiable.push_back(d);
    }
  }
  block.basis = basis;
  RenumberJointBlocks(p, static_cast<size_t>(b));
}

void AddBilinearBlock(std::shared_ptr<const BilinearJointEffect> effect, int partner,
                      Parameterization* p) {
  CHECK(effect != nullptr);
  CHECK(partner >= 0 && partner < static_cast<int>(p->joint_blocks.size()));
  CHECK_EQ(p->joint_blocks[partner].term->name(), effect->partner());
  BilinearBlock block;
  block.effect = std::move(effect);
  block.partner = partner;
  p->bilinear_blocks.push_back(std::move(block));
  RenumberJointBlocks(p);
}

void CopyJointBlocks(const Parameterization& from, Parameterization* to) {
  to->joint_blocks = from.joint_blocks;
  to->bilinear_blocks = from.bilinear_blocks;
  std::vector<Direction> lost;
  for (const Direction& d : to->unidentifiable) {
    if (d.joint_block < 0) lost.push_back(d);
  }
  for (const Direction& d : from.unidentifiable) {
    if (d.joint_block >= 0) lost.push_back(d);
  }
  to->unidentifiable = std::move(lost);
  RenumberJointBlocks(to);
}

std::vector<JointTermValues> JointValuesOf(const Parameterization& p, const Eigen::VectorXd& x) {
  CHECK_EQ(x.size(), p.num_parameters);
  std::vector<JointTermValues> out;
  for (const JointBlock& block : p.joint_blocks) {
    JointTermValues v;
    v.term = block.term;
    v.theta = block.basis * x.segment(block.offset, block.basis.cols());
    out.push_back(std::move(v));
  }
  for (size_t b = 0; b < p.bilinear_blocks.size(); ++b) {
    const BilinearBlock& block = p.bilinear_blocks[b];
    const Eigen::VectorXd t = BilinearValuesOf(p, static_cast<int>(b), x);
    std::shared_ptr<const JointTerm> term;
    const Status s = block.effect->PartnerAt(*out[block.partner].term, t.data(), &term);
    CHECK(s.ok()) << s.message();
    out[block.partner].term = std::move(term);
  }
  return out;
}

Eigen::VectorXd BilinearValuesOf(const Parameterization& p, int b, const Eigen::VectorXd& x) {
  CHECK_EQ(x.size(), p.num_parameters);
  const BilinearBlock& block = p.bilinear_blocks[b];
  return x.segment(block.offset, block.effect->num_parameters());
}

void ApplyUpdate(const Parameterization& p, const Eigen::VectorXd& x, RobotModel* model) {
  CHECK_EQ(x.size(), p.num_parameters);
  const int n = model->num_joints();
  for (int f = 0; f < model->num_frames(); ++f) {
    const Eigen::MatrixXd& B = p.basis[f];  // frames only: the joint blocks are not in the model
    if (B.cols() == 0) continue;
    const Vector6d dp = B * x.segment(p.offset[f], B.cols());
    SE3d& T = f < n ? model->joints[f].origin : model->tools[f - n].origin;
    T = T * ExpSE3(dp);  // eq. (19)
  }
}

Eigen::VectorXd ParameterDifference(const Parameterization& p, const RobotModel& a,
                                    const RobotModel& b) {
  CHECK_EQ(a.num_frames(), b.num_frames());
  const int n = a.num_joints();
  Eigen::VectorXd x = Eigen::VectorXd::Zero(p.num_parameters);  // joint blocks: zero
  for (int f = 0; f < a.num_frames(); ++f) {
    const SE3d& Ta = f < n ? a.joints[f].origin : a.tools[f - n].origin;
    const SE3d& Tb = f < n ? b.joints[f].origin : b.tools[f - n].origin;
    const Vector6d d = LogSE3(Ta.Inverse() * Tb);
    x.segment(p.offset[f], p.basis[f].cols()) = p.basis[f].transpose() * d;
  }
  return x;
}

}  // namespace lpoe
