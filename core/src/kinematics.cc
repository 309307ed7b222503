#include "lpoe/kinematics.h"

#include <cmath>

#include <glog/logging.h>

namespace lpoe {

SE3d JointMotion(const Joint& joint, double q) {
  SE3d X;
  if (joint.type == JointType::kPrismatic) {
    X.t = joint.twist.tail<3>() * q;
    return X;
  }
  const Vector6d& s = joint.twist;
  if (s(0) == 0 && s(1) == 0 && s(2) == 1 && s(3) == 0 && s(4) == 0 && s(5) == 0) {
    const double c = std::cos(q), sn = std::sin(q);
    X.R << c, -sn, 0, sn, c, 0, 0, 0, 1;
    return X;
  }
  return ExpSE3(Vector6d(s * q));
}

SE3d ToolPose(const RobotModel& model, const double* q, int tool) {
  DCHECK(tool >= 0 && tool < model.num_tools());
  SE3d X;
  for (int i = 0; i < model.num_joints(); ++i) {
    X = X * model.joints[i].origin * JointMotion(model.joints[i], q[i]);
  }
  return X * model.tools[tool].origin;
}

Eigen::Vector3d ToolPosition(const RobotModel& model, const double* q, int tool) {
  DCHECK(tool >= 0 && tool < model.num_tools());
  SE3d X;
  for (int i = 0; i < model.num_joints(); ++i) {
    X = X * model.joints[i].origin * JointMotion(model.joints[i], q[i]);
  }
  return X * model.tools[tool].origin.t;
}

void PerturbationFrames(const RobotModel& model, const double* q, int tool,
                        std::vector<SE3d>* frames) {
  const int n = model.num_joints();
  frames->resize(n + 1);
  SE3d X;
  for (int i = 0; i < n; ++i) {
    X = X * model.joints[i].origin;
    (*frames)[i] = X;
    X = X * JointMotion(model.joints[i], q[i]);
  }
  (*frames)[n] = X * model.tools[tool].origin;
}

Eigen::Vector3d ToolPositionJacobian(const RobotModel& model, const double* q, int tool,
                                     Eigen::MatrixXd* J_p_frames) {
  const int n = model.num_joints();
  std::vector<SE3d> G;
  PerturbationFrames(model, q, tool, &G);
  const Eigen::Vector3d P = G[n].t;
  J_p_frames->setZero(3, 6 * model.num_frames());
  for (int f = 0; f <= n; ++f) {
    const int col = 6 * (f < n ? f : n + tool);
    // dP = (R w) x (P - t) + R v  =>  d/dw = -(P - t)^ R, d/dv = R   (eq. (29) without Ad).
    J_p_frames->block<3, 3>(0, col) = -Hat3(Eigen::Vector3d(P - G[f].t)) * G[f].R;
    J_p_frames->block<3, 3>(0, col + 3) = G[f].R;
  }
  return P;
}

SE3d ToolPoseJacobian(const RobotModel& model, const double* q, int tool,
                      Eigen::MatrixXd* J_pose_frames) {
  const int n = model.num_joints();
  std::vector<SE3d> G;
  PerturbationFrames(model, q, tool, &G);
  J_pose_frames->setZero(6, 6 * model.num_frames());
  for (int f = 0; f <= n; ++f) {
    const int col = 6 * (f < n ? f : n + tool);
    J_pose_frames->block<6, 6>(0, col) = Adjoint(G[f]);  // eq. (18)
  }
  return G[n];
}

}  // namespace lpoe
