#include "calibration/gravity_tilt.h"

#include <cmath>
#include <sstream>
#include <vector>

#include <Eigen/Eigenvalues>
#include <glog/logging.h>

#include "calibration/block_kind.h"
#include "calibration/problem_setup.h"
#include "identifiability/identifiability.h"
#include "lpoe/kinematics/eigen_decompositions.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "linearization/normal_equations.h"

namespace lpoe {
namespace internal {
namespace {

// The term the tilt is bilinear with and the message without it (the kind's, below).
constexpr char kTiltPartner[] = "compliance";
constexpr char kTiltNeedsPartner[] =
    "the gravity tilt is identified with the compliance term (joint errors compliance,tilt)";

}  // namespace

void GravityTiltRowRegressors(const Parameterization& p, const double* q, Eigen::MatrixXd Z[3]) {
  CHECK(p.gravity_tilt != nullptr);
  const JointBlock& block = p.joint_blocks[p.tilt_block];
  const int n = p.gravity_tilt->reference().num_joints();
  const int P = NumComplianceParameters(n);
  CHECK_EQ(block.basis.rows(), P) << "the tilt's block is not the compliance term";
  const Eigen::Index k = block.basis.cols();
  // Y_a's entries at their joints only: row j of Z_a = Y_a(j, joint j's parameters) times those
  // rows of the basis (the dense n x P product's zeros skipped; about n times fewer products).
  thread_local std::vector<double> values;
  values.resize(3 * static_cast<size_t>(P));
  double* const y[3] = {values.data(), values.data() + P, values.data() + 2 * P};
  p.gravity_tilt->AxisValues(q, y);
  for (int a = 0; a < 3; ++a) Z[a].resize(n, k);
  // Z_a(j, i) = basis column i's joint-j segment . y_a's joint-j segment: contiguous in both, the
  // three axes in one pass over the basis.
  const double* B = block.basis.data();
  for (int j = 0; j < n; ++j) {
    const int first = ComplianceLinkIndex(n, j, j);
    const int count = CompliancePayloadIndex(n, j) - first + 1;
    const double* y0 = y[0] + first;
    const double* y1 = y[1] + first;
    const double* y2 = y[2] + first;
    for (Eigen::Index i = 0; i < k; ++i) {
      const double* b = B + i * P + first;
      double z0 = 0, z1 = 0, z2 = 0;
      for (int c = 0; c < count; ++c) {
        z0 += b[c] * y0[c];
        z1 += b[c] * y1[c];
        z2 += b[c] * y2[c];
      }
      Z[0](j, i) = z0;
      Z[1](j, i) = z1;
      Z[2](j, i) = z2;
    }
  }
}

void ApplyGravityTiltColumns(const Parameterization& p, const double* q,
                             const Eigen::VectorXd& joint_state, Eigen::Ref<Eigen::MatrixXd> R,
                             Eigen::VectorXd* q_eff) {
  if (!p.gravity_tilt) return;
  const int F = p.num_frame_parameters();
  const JointBlock& block = p.joint_blocks[p.tilt_block];
  const int k = static_cast<int>(block.basis.cols());
  const int c0 = block.offset - F;  // the compliance block's first column in R
  const int t0 = p.tilt_offset - F;  // the tilt's first column
  // Per-thread scratch: called for every row of every linearization.
  struct Scratch {
    Eigen::VectorXd x, ddq;
    Eigen::MatrixXd Z[3], dR, D;
  };
  thread_local Scratch s;
  s.x.setZero(k);
  double tilt[2] = {0, 0};
  if (joint_state.size() > 0) {
    s.x = joint_state.segment(c0, k);
    tilt[0] = joint_state(t0);
    tilt[1] = joint_state(t0 + 1);
  }
  GravityTiltRowRegressors(p, q, s.Z);
  GravityTiltJointColumns(p.gravity_tilt->gravity(), p.gravity_tilt->axes(), tilt, s.Z, s.x.data(),
                          &s.ddq, &s.dR, &s.D);
  R.middleCols(c0, k) += s.dR;
  R.middleCols(t0, 2) = s.D;
  *q_eff += s.ddq;
}

Status AddSolverGravityTilt(std::shared_ptr<const GravityTiltModel> tilt, Parameterization* p) {
  for (size_t b = 0; b < p->joint_blocks.size(); ++b) {
    if (p->joint_blocks[b].term->name() != kTiltPartner) continue;
    if (p->joint_blocks[b].basis.cols() == 0) {
      return Status::Error("the gravity tilt needs identified compliance combinations; these data "
                           "identify none");
    }
    AddGravityTilt(std::move(tilt), static_cast<int>(b), p);
    return Status::Ok();
  }
  return Status::Error(kTiltNeedsPartner);
}

Eigen::VectorXd InitialJointState(const Parameterization& p,
                                  const std::vector<JointTermValues>& initial) {
  const int F = p.num_frame_parameters();
  Eigen::VectorXd x = Eigen::VectorXd::Zero(p.num_joint_parameters());
  for (const JointBlock& block : p.joint_blocks) {
    for (const JointTermValues& v : initial) {
      if (v.term == nullptr || v.term->name() != block.term->name()) continue;
      CHECK_EQ(v.theta.size(), block.basis.rows()) << block.term->name();
      x.segment(block.offset - F, block.basis.cols()) = block.basis.transpose() * v.theta;
    }
  }
  return x;
}

void FillGravityTiltResult(const Parameterization& p, const Eigen::VectorXd& joint_state,
                           const Eigen::MatrixXd& covariance, GravityTiltResult* out) {
  if (!p.gravity_tilt) return;
  const int t0 = p.tilt_offset - p.num_frame_parameters();
  out->identified = true;
  out->tilt = joint_state.size() > 0 ? Eigen::Vector2d(joint_state.segment<2>(t0))
                                     : Eigen::Vector2d::Zero();
  out->axes = p.gravity_tilt->axes();
  out->gravity_before = p.gravity_tilt->gravity();
  out->gravity_after = p.gravity_tilt->Tilted(out->tilt.data());
  out->standard_deviation.setZero();
  if (covariance.rows() == p.num_parameters) {
    for (int a = 0; a < 2; ++a) {
      out->standard_deviation(a) = std::sqrt(std::max(0.0, covariance(p.tilt_offset + a,
                                                                       p.tilt_offset + a)));
    }
  }
  out->message.clear();
}

bool CheckGravityTilt(const RobotModel& start, const MeasurementSet& data,
                      const CalibrationResult& r0, bool use_orientation, double orientation_weight,
                      double tolerance, double max_sigma, GravityTiltResult* out) {
  auto tilt = std::make_shared<const GravityTiltModel>(start);
  out->axes = tilt->axes();
  out->gravity_before = tilt->gravity();
  out->gravity_after = tilt->gravity();
  auto refuse = [&](const std::string& why) {
    out->message = "gravity tilt not identifiable from these data; kept at the model's gravity (" +
                   why + ")";
    return false;
  };
  Parameterization p = r0.parameterization;
  LeaveOutUnmeasuredTools(r0.model, data, &p);
  if (Status s = AddSolverGravityTilt(tilt, &p); !s.ok()) return refuse(s.message());
  Eigen::VectorXd state = InitialJointState(p, r0.joint_terms);
  NormalEquationsOptions rows;
  rows.use_orientation = use_orientation;
  rows.orientation_weight = orientation_weight;
  const NormalEquations lin = NormalEquationsOf(r0.model, data, p, state, rows);
  if (!lin.finite) return refuse("non-finite normal equations");
  const int P = p.num_parameters;
  const int o = P - 2;
  // Column scaling; a zero column (nothing moves) keeps scale 0.
  Eigen::VectorXd d(P);
  for (int k = 0; k < P; ++k) d(k) = lin.H(k, k) > 0 ? 1.0 / std::sqrt(lin.H(k, k)) : 0.0;
  if (d(o) == 0 || d(o + 1) == 0) return refuse("the tilt moves no measured point");
  const Eigen::MatrixXd Hs = d.asDiagonal() * lin.H * d.asDiagonal();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(Hs.topLeftCorner(o, o));
  const Eigen::VectorXd& l = eig.eigenvalues();
  const double largest = l.size() > 0 ? l.maxCoeff() : 0.0;
  Eigen::VectorXd inv = Eigen::VectorXd::Zero(l.size());
  for (int k = 0; k < l.size(); ++k) {
    if (l(k) > 1e-12 * largest) inv(k) = 1.0 / l(k);
  }
  const Eigen::MatrixXd B = eig.eigenvectors().transpose() * Hs.topRightCorner(o, 2);
  const Eigen::Matrix2d M = Hs.bottomRightCorner<2, 2>() - B.transpose() * inv.asDiagonal() * B;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> m_eig(M);
  out->kept_fraction = std::sqrt(std::max(0.0, m_eig.eigenvalues()(0)));
  const int per_row = TrackerResiduals(TrackerKindId(use_orientation));
  const long dof = static_cast<long>(per_row) * data.size() - P;
  const double s2 = dof > 0 ? 2.0 * lin.cost / static_cast<double>(dof) : 0.0;
  if (out->kept_fraction >= tolerance && m_eig.eigenvalues()(0) > 0) {
    const Eigen::Matrix2d C = s2 * (d.tail<2>().asDiagonal() * M.inverse() *
                                    d.tail<2>().asDiagonal());
    out->predicted_standard_deviation << std::sqrt(C(0, 0)), std::sqrt(C(1, 1));
  } else {
    out->predicted_standard_deviation.setConstant(INFINITY);
  }
  std::ostringstream why;
  constexpr double kDeg = 180.0 / M_PI;
  if (out->kept_fraction < tolerance) {
    why << "its effect is not separable from the geometry and the other terms: kept fraction "
        << out->kept_fraction << " < " << tolerance;
    return refuse(why.str());
  }
  const double worst = out->predicted_standard_deviation.maxCoeff();
  if (!(worst <= max_sigma)) {
    why << "the compliance torques at these poses determine it only to " << worst * kDeg
        << " deg (1 sigma), above the limit of " << max_sigma * kDeg << " deg";
    return refuse(why.str());
  }
  out->message.clear();
  return true;
}

namespace {

// The gravity tilt as a block kind (block_kind.h): two parameters after the joint blocks, bilinear
// with the compliance block; the functions above are its columns, result and rule.
class GravityTiltKind : public BlockKind {
 public:
  const char* name() const override { return kGravityTiltName; }
  const char* partner_term() const override { return kTiltPartner; }
  const char* needs_partner_message() const override { return kTiltNeedsPartner; }
  bool Requested(const ProblemSetupRequest& request) const override {
    return request.gravity_tilt != nullptr;
  }
  bool In(const Parameterization& p) const override { return p.gravity_tilt != nullptr; }
  // One block of two numbers (rad) after the joint blocks, from the request's initial values.
  void AppendBlocks(const ProblemSetup& setup, const RobotModel& /*nominal*/,
                    std::vector<ProblemBlock>* out) const override {
    const Parameterization& p = setup.all;
    if (!In(p)) return;
    const int t0 = p.tilt_offset - p.num_frame_parameters();
    ProblemBlock b;
    b.kind = this;
    b.offset = p.tilt_offset;
    b.tangent_size = 2;
    b.values = {setup.initial_joint_state(t0), setup.initial_joint_state(t0 + 1)};
    b.initial = b.values;
    out->push_back(std::move(b));
  }
  // J_q(q_eff) d(dq)/dt at the current compliance coordinates and tilt.
  void Columns(const BlockColumnsContext& ctx, const ProblemBlock& block,
               const MeasurementSet& data, int r, Eigen::MatrixXd* J) const override {
    RowLinearization row;
    LinearizeRow(ctx, data, r, &row);
    *J = row.J_q * row.R.middleCols(block.offset - ctx.p->num_frame_parameters(), 2);
  }
  Status Add(const ProblemSetupRequest& request, Parameterization* p) const override {
    return AddSolverGravityTilt(request.gravity_tilt, p);
  }
  void RowColumns(const Parameterization& p, const double* q, const Eigen::VectorXd& joint_state,
                  Eigen::Ref<Eigen::MatrixXd> R, Eigen::VectorXd* q_eff) const override {
    ApplyGravityTiltColumns(p, q, joint_state, R, q_eff);
  }
  std::shared_ptr<const GravityTiltRow> CeresRow(const Parameterization& p, const double* q,
                                                 int partner_block) const override {
    auto row = std::make_shared<GravityTiltRow>();
    row->block = partner_block;
    row->gravity = p.gravity_tilt->gravity();
    row->axes = p.gravity_tilt->axes();
    GravityTiltRowRegressors(p, q, row->Z);
    return row;
  }
  void FillResult(const Parameterization& p, const Eigen::VectorXd& joint_state,
                  const Eigen::MatrixXd& covariance, CalibrationResult* out) const override {
    FillGravityTiltResult(p, joint_state, covariance, &out->gravity_tilt);
  }
  bool Identifiable(const RobotModel& start, const MeasurementSet& data,
                    const CalibrationResult& r0, bool use_orientation, double orientation_weight,
                    double tolerance, double max_sigma, CalibrationResult* out) const override {
    return CheckGravityTilt(start, data, r0, use_orientation, orientation_weight, tolerance,
                            max_sigma, &out->gravity_tilt);
  }
};

}  // namespace

const BlockKind& GravityTiltBlockKind() {
  static const GravityTiltKind kind;
  return kind;
}

}  // namespace internal
}  // namespace lpoe
