// Pose residual of one tracker measurement with orientation (paper eqs. (17), (18)), weighted and
// whitened:
//
//   y = log(T_measured * T_model(q)^-1)^vee = (omega, v)                 (eq. (17))
//   r = diag(w, w, w, 1, 1, 1) * y / sigma                                (6 residuals)
//
//   T_model(q) = T_0,1(0) exp(s_1^ q_1) ... T_n-1,n(0) exp(s_n^ q_n) T_n,tool   (eq. (7))
//
// w = orientation_weight (mm per rad) puts the rotation rows on the millimetre scale of the
// translation rows (1 rad counts as w mm), as in the linear solver. Parameter blocks: the n joint
// frames, then the measured tool's frame, 7 numbers each ([qx qy qz qw tx ty tz]).
//
// Near the solution y -> 0 and d r / d(right perturbations) -> -diag(w,..,1) A / sigma with A the
// adjoint stack of eq. (18) (kinematics.h ToolPoseJacobian).
#ifndef LPOE_POSE_RESIDUAL_H_
#define LPOE_POSE_RESIDUAL_H_

#include <memory>
#include <vector>

#include <ceres/dynamic_autodiff_cost_function.h>

#include "lpoe/kinematics.h"
#include "lpoe/robot_model.h"
#include "lpoe/se3_manifold.h"

namespace lpoe {

class PoseResidual {
 public:
  static constexpr int kNumResiduals = 6;
  static constexpr int kStride = 2;  // see PositionResidual::kStride
  using CostFunction = ceres::DynamicAutoDiffCostFunction<PoseResidual, kStride>;

  // `model` supplies the twists; `q` holds model->num_joints() values; sigma > 0 (mm);
  // orientation_weight > 0 (mm per rad).
  PoseResidual(std::shared_ptr<const RobotModel> model, const double* q, const SE3d& measured,
               double sigma, double orientation_weight)
      : model_(std::move(model)),
        q_(q, q + model_->num_joints()),
        measured_R_(measured.R),
        measured_t_(measured.t),
        inverse_sigma_(1.0 / sigma),
        orientation_weight_(orientation_weight) {}

  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    const int n = model_->num_joints();
    std::vector<SE3<T>> frames(n);
    for (int i = 0; i < n; ++i) frames[i] = Se3FromArray(parameters[i]);
    const SE3<T> tool = Se3FromArray(parameters[n]);
    const SE3<T> model_pose = ChainPose(*model_, frames.data(), tool, q_.data());
    const SE3<T> measured(measured_R_.cast<T>(), measured_t_.cast<T>());
    const Vector6<T> y = LogSE3(measured * model_pose.Inverse());  // eq. (17)
    const T rotation_scale = T(orientation_weight_ * inverse_sigma_);
    for (int k = 0; k < 3; ++k) residuals[k] = y(k) * rotation_scale;
    for (int k = 3; k < 6; ++k) residuals[k] = y(k) * T(inverse_sigma_);
    return true;
  }

  // The cost function with n + 1 parameter blocks of 7 and 6 residuals (defined in residuals.cc).
  static ceres::CostFunction* Create(std::shared_ptr<const RobotModel> model, const double* q,
                                     const SE3d& measured, double sigma,
                                     double orientation_weight);

 private:
  std::shared_ptr<const RobotModel> model_;
  std::vector<double> q_;
  Eigen::Matrix3d measured_R_;
  Eigen::Vector3d measured_t_;
  double inverse_sigma_;
  double orientation_weight_;
};

}  // namespace lpoe

#endif  // LPOE_POSE_RESIDUAL_H_
