#include "lpoe/measurements/measurement_model.h"

#include <glog/logging.h>

namespace lpoe {
namespace {

std::vector<double> EffectiveJoints(const RobotModel& model,
                                    const std::vector<JointTermValues>& terms, const double* q) {
  std::vector<double> q_eff(model.num_joints());
  EffectiveJointValues(terms, model.num_joints(), q, q_eff.data());
  return q_eff;
}

}  // namespace

Eigen::Vector3d PredictPosition(const RobotModel& model, const std::vector<JointTermValues>& terms,
                                const double* q, int tool) {
  if (terms.empty()) return ToolPosition(model, q, tool);
  return ToolPosition(model, EffectiveJoints(model, terms, q).data(), tool);
}

SE3d PredictPose(const RobotModel& model, const std::vector<JointTermValues>& terms,
                 const double* q, int tool) {
  if (terms.empty()) return ToolPose(model, q, tool);
  return ToolPose(model, EffectiveJoints(model, terms, q).data(), tool);
}

Eigen::Vector3d PredictPositionJacobian(const RobotModel& model, const Parameterization& p,
                                        const std::vector<JointTermValues>& terms,
                                        const double* q, int tool, Eigen::MatrixXd* J_p_x) {
  CHECK_EQ(terms.size(), p.joint_blocks.size());
  const std::vector<double> q_eff = EffectiveJoints(model, terms, q);
  const int n = model.num_joints();
  const BasisJacobian bj(model, p);
  std::vector<FrameRt> frames(n + 1);
  J_p_x->setZero(3, p.num_parameters);
  Eigen::MatrixXd J_q(3, n);
  const Eigen::Vector3d P = bj.Position(q_eff.data(), tool, J_p_x->data(), 3, frames.data());
  bj.PositionJointJacobian(frames.data(), J_q.data(), 3);
  for (const JointBlock& block : p.joint_blocks) {
    Eigen::MatrixXd Y(n, block.term->num_parameters());
    block.term->Regressor(q, Y.data());
    J_p_x->middleCols(block.offset, block.basis.cols()) = J_q * Y * block.basis;
  }
  return P;
}

Eigen::Vector3d PredictPositionJointJacobian(const RobotModel& model,
                                             const std::vector<JointTermValues>& terms,
                                             const double* q, int tool, Eigen::MatrixXd* J_p_q) {
  return ToolPositionJointJacobian(model, EffectiveJoints(model, terms, q).data(), tool, J_p_q);
}

}  // namespace lpoe
