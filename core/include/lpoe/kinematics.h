// Forward kinematics of the LPoE chain (paper eqs. (6), (7), (26)) and the analytic Jacobians of the
// error model (eqs. (18), (29)).
//
// The chain is written once, as a template on the scalar of the local frames: doubles for the linear
// solver and the tools, ceres::Jet for automatic differentiation (the Ceres residuals pass their
// parameter blocks as frames). Joint values and twists are data, always double.
#ifndef LPOE_KINEMATICS_H_
#define LPOE_KINEMATICS_H_

#include <vector>

#include "lpoe/robot_model.h"
#include "lpoe/se3.h"

namespace lpoe {

// exp(s^ q) for a joint of the given twist. Revolute joints about local z (the common case) take a
// closed form with one sin/cos pair.
SE3d JointMotion(const Joint& joint, double q);

// T_0,tool(q) = prod_i T_{i-1,i}(0) exp(s_i^ q_i) * T_n,tool with the local frames given by
// `joint_origins[0..n)` and `tool_origin` (paper eq. (7)). `q` holds n joint values.
template <typename T>
SE3<T> ChainPose(const RobotModel& model, const SE3<T>* joint_origins, const SE3<T>& tool_origin,
                 const double* q) {
  SE3<T> X = joint_origins[0];
  for (int i = 0; i < model.num_joints(); ++i) {
    if (i > 0) X = X * joint_origins[i];
    X = X * JointMotion(model.joints[i], q[i]).template cast<T>();
  }
  return X * tool_origin;
}

// Position-only variant (eq. (26)): P = T_0,n(q) * p_tool. Saves the last rotation product.
template <typename T>
Vector3<T> ChainPosition(const RobotModel& model, const SE3<T>* joint_origins,
                         const Vector3<T>& tool_point, const double* q) {
  SE3<T> X = joint_origins[0];
  for (int i = 0; i < model.num_joints(); ++i) {
    if (i > 0) X = X * joint_origins[i];
    X = X * JointMotion(model.joints[i], q[i]).template cast<T>();
  }
  return X * tool_point;
}

// Convenience forms on the model's own frames (double).
SE3d ToolPose(const RobotModel& model, const double* q, int tool = 0);
Eigen::Vector3d ToolPosition(const RobotModel& model, const double* q, int tool = 0);

// Frame of every joint at configuration q: G_i = T_0,i-1(q) T_{i-1,i}(0) (before joint i moves),
// i = 0..n-1, followed by the tool frame T_0,n(q) T_n,tool. This is where a right perturbation of
// local frame i acts: T_0,tool(perturbed) = exp((Ad_{G_i} dp_i)^) T_0,tool.
void PerturbationFrames(const RobotModel& model, const double* q, int tool,
                        std::vector<SE3d>* frames);

// Jacobian of the tool position with respect to the right perturbations dp_i (omega, v) of every
// local frame (paper eq. (29)): J = [-P^ I3] [Ad_G_0 ... Ad_G_n-1, Ad_G_tool]. Written without the
// 6x6 adjoints: for frame G = (R, t), dP/d omega = -(P - t)^ R, dP/d v = R.
// `J_p_frames` is resized to 3 x 6 * model.num_frames(); the columns of tools other than `tool` are
// zero. Returns P.
Eigen::Vector3d ToolPositionJacobian(const RobotModel& model, const double* q, int tool,
                                     Eigen::MatrixXd* J_p_frames);

// Jacobian of the pose error log(T_measured T_model^-1)^vee with respect to the same perturbations
// (paper eq. (18)): J = [Ad_G_0 ... Ad_G_tool], 6 x 6 * num_frames. Returns T_0,tool(q).
SE3d ToolPoseJacobian(const RobotModel& model, const double* q, int tool,
                      Eigen::MatrixXd* J_pose_frames);

}  // namespace lpoe

#endif  // LPOE_KINEMATICS_H_
