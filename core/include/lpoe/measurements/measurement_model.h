// The measurement model: what the robot model predicts for a measurement, and its derivatives
// (docs/architecture.md). This is the one place both solvers, the analysis and the tools get a
// prediction from.
//
//   q_eff = q + sum_terms Y_term(q) theta_term                      (joint_term.h)
//   P     = FK(q_eff) p_tool,    T = FK(q_eff) T_n,tool              (kinematics.h, eq. (7))
//
// Measurement kinds (position_measurement.h, pose_measurement.h) carry the templated prediction on
// parameter blocks (Ceres autodiff, double or Jet joint values) and the analytic linearization (the
// linear solver). The free functions below are the stable double entry points for other code: the
// prediction with identified joint terms and its Jacobians with respect to the parameters of a
// Parameterization and to the joint values.
#ifndef LPOE_MEASUREMENT_MODEL_H_
#define LPOE_MEASUREMENT_MODEL_H_

#include <vector>

#include <Eigen/Core>

#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/measurements/pose_measurement.h"
#include "lpoe/measurements/position_measurement.h"
#include "lpoe/model/robot_model.h"

namespace lpoe {

// The tool position / pose at joint values q (model's frame), with the joint terms applied.
Eigen::Vector3d PredictPosition(const RobotModel& model, const std::vector<JointTermValues>& terms,
                                const double* q, int tool = 0);
SE3d PredictPose(const RobotModel& model, const std::vector<JointTermValues>& terms,
                 const double* q, int tool = 0);

// The predicted position and dP/dx (3 x p.num_parameters): the frame columns in p's bases at
// q_eff (eq. (29)), the joint-block columns J_q(q_eff) Y_b(q) basis_b. `terms` holds the values of
// p's joint blocks, in the same order (empty when p has none). Returns P.
Eigen::Vector3d PredictPositionJacobian(const RobotModel& model, const Parameterization& p,
                                        const std::vector<JointTermValues>& terms,
                                        const double* q, int tool, Eigen::MatrixXd* J_p_x);

// The predicted position and dP/dq (3 x n), the derivative with respect to the joint values the
// terms are applied to (at q_eff; the terms' own dependence on q is not included). Returns P.
Eigen::Vector3d PredictPositionJointJacobian(const RobotModel& model,
                                             const std::vector<JointTermValues>& terms,
                                             const double* q, int tool, Eigen::MatrixXd* J_p_q);

}  // namespace lpoe

#endif  // LPOE_MEASUREMENT_MODEL_H_
