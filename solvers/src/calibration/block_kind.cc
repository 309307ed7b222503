#include "calibration/block_kind.h"

#include <glog/logging.h>

#include "linearization/joint_term_columns.h"
#include "calibration/problem_setup.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/pose_measurement.h"
#include "lpoe/measurements/position_measurement.h"

namespace lpoe {
namespace internal {

#define LPOE_BLOCK_KIND(Entry) const BlockKind& Entry();
#include "calibration/block_kind_registry.inc"
#undef LPOE_BLOCK_KIND

const std::vector<const BlockKind*>& BlockKinds() {
  static const std::vector<const BlockKind*> kinds = {
#define LPOE_BLOCK_KIND(Entry) &Entry(),
#include "calibration/block_kind_registry.inc"
#undef LPOE_BLOCK_KIND
  };
  return kinds;
}

const BlockKind* FindBlockKind(const std::string& name) {
  for (const BlockKind* kind : BlockKinds()) {
    if (name == kind->name()) return kind;
  }
  return nullptr;
}

const BilinearBlockKind* FindBilinearBlockKind(const std::string& name) {
  const BlockKind* kind = FindBlockKind(name);
  return kind != nullptr ? kind->bilinear() : nullptr;
}

void BlockKind::AddManifold(const Parameterization& /*p*/, ProblemBlock* /*block*/,
                            ceres::Problem* /*problem*/) const {}

void BlockKind::Plus(const Parameterization& /*p*/, const Eigen::VectorXd& x, int offset,
                     ProblemBlock* block, RobotModel* /*model*/) const {
  for (size_t c = 0; c < block->values.size(); ++c) block->values[c] += x(offset + c);
}

void BlockKind::WriteModel(const ProblemBlock& /*block*/, RobotModel* /*model*/) const {}

void BlockKind::WriteCoordinates(const ProblemBlock& block, Eigen::VectorXd* x) const {
  for (size_t c = 0; c < block.values.size(); ++c) (*x)(block.offset + c) = block.values[c];
}

bool BlockKind::AtReductionPoint(const ProblemBlock& block) const {
  for (double v : block.values) {
    if (v != 0) return false;
  }
  return true;
}

void LinearizeRow(const BlockColumnsContext& ctx, const MeasurementSet& data, int r,
                  RowLinearization* out) {
  const RobotModel& model = *ctx.model;
  const Parameterization& p = *ctx.p;
  const int n = model.num_joints();
  const int K = p.num_joint_parameters();
  const int m = ctx.use_orientation ? 6 : 3;
  const double* q = data.q(r);
  // The joint-space columns at the current values and q_eff = q + R x (+ the kinds' change).
  Eigen::VectorXd q_eff = Eigen::Map<const Eigen::VectorXd>(q, n);
  out->R.setZero(n, K);
  if (K > 0) {
    JointTermColumns columns(p, n, K);
    columns.Evaluate(r, q, &out->R);
    const Eigen::VectorXd& x = *ctx.joint_state;
    if (x.size() > 0) q_eff.noalias() += out->R * x;
    AddNonlinearRowColumns(p, q, x, out->R, &q_eff);
  }
  const BasisJacobian bj(model, p);
  std::vector<FrameRt> frames(n + 1);
  out->J.setZero(m, p.num_parameters);
  out->J_q.setZero(m, n);
  double y[6];
  if (ctx.use_orientation) {
    PoseMeasurement kind;
    kind.orientation_weight = ctx.orientation_weight;
    kind.Linearize(bj, q_eff.data(), data.target(r), PoseMeasurement::Observe(data, r),
                   out->J.data(), m, out->J_q.data(), m, frames.data(), y);
  } else {
    PositionMeasurement kind;
    kind.Linearize(bj, q_eff.data(), data.target(r), PositionMeasurement::Observe(data, r),
                   out->J.data(), m, out->J_q.data(), m, frames.data(), y);
  }
  out->J.rightCols(K).setZero();
}

void FillBlockKindResults(const Parameterization& p, const Eigen::VectorXd& joint_state,
                          const Eigen::MatrixXd& covariance, CalibrationResult* out) {
  for (const BlockKind* kind : BlockKinds()) {
    const BilinearBlockKind* bilinear = kind->bilinear();
    if (bilinear != nullptr && bilinear->In(p)) {
      bilinear->FillResult(p, joint_state, covariance, out);
    }
  }
}

}  // namespace internal
}  // namespace lpoe
