// Position residual of one tracker measurement (paper eqs. (26), (30)), whitened:
//
//   r = (P_model(q) - P_measured) / sigma                                  (3 residuals, mm / mm)
//
//   P_model(q) = T_0,1(0) exp(s_1^ q_1) T_1,2(0) exp(s_2^ q_2) ... T_n-1,n(0) exp(s_n^ q_n) p_tool
//
// where T_{i-1,i}(0) are the n joint frames and p_tool the translation of the measured tool frame
// T_n,tool. Parameter blocks: the n joint frames, then the measured tool's frame, 7 numbers each
// ([qx qy qz qw tx ty tz], see se3_manifold.h). The tool's rotation does not enter (zero columns):
// give that block a manifold restricted to translations (the identifiable tool basis).
//
// The chain is the core's templated ChainPosition, so the double and Jet paths are the same code.
// Joint values, twists and the measurement are data (double).
#ifndef LPOE_POSITION_RESIDUAL_H_
#define LPOE_POSITION_RESIDUAL_H_

#include <memory>
#include <vector>

#include <Eigen/Core>
#include <ceres/dynamic_autodiff_cost_function.h>

#include "lpoe/kinematics.h"
#include "lpoe/robot_model.h"
#include "lpoe/se3_manifold.h"

namespace lpoe {

class PositionResidual {
 public:
  static constexpr int kNumResiduals = 3;
  // Derivatives per autodiff pass. Each pass evaluates the whole chain on Jet<double, kStride>;
  // measured on the 6R chain (49 parameters, -O3, no -march): stride 1: 46 us per Jacobian,
  // 2: 19 us, 4: 51 us, 7: 90 us, 8: 90 us. Jet<double, 2> fills one SSE register and inlines.
  static constexpr int kStride = 2;
  // Chains up to this many joints keep their frames on the stack.
  static constexpr int kMaxStackJoints = 16;
  using CostFunction = ceres::DynamicAutoDiffCostFunction<PositionResidual, kStride>;

  // `model` supplies the joints' twists (its frames are ignored: they are the parameters); `q` holds
  // model->num_joints() values; sigma > 0 (mm).
  PositionResidual(std::shared_ptr<const RobotModel> model, const double* q,
                   const Eigen::Vector3d& measured, double sigma)
      : model_(std::move(model)),
        motions_(*model_, q),
        measured_(measured),
        inverse_sigma_(1.0 / sigma) {}

  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    // The frames act on the point straight from their quaternions (no rotation matrices): the
    // manifold keeps each block's quaternion of unit norm.
    const int n = model_->num_joints();
    QuaternionTransform<T> stack_frames[kMaxStackJoints];
    std::vector<QuaternionTransform<T>> heap_frames;
    QuaternionTransform<T>* frames = stack_frames;
    if (n > kMaxStackJoints) {
      heap_frames.resize(n);
      frames = heap_frames.data();
    }
    for (int i = 0; i < n; ++i) frames[i] = {parameters[i], parameters[i] + 4};
    const T* tool = parameters[n];
    const Vector3<T> p_tool(tool[4], tool[5], tool[6]);
    const Vector3<T> P = ChainPosition<T>(motions_, n, frames, p_tool);
    for (int k = 0; k < 3; ++k) residuals[k] = (P(k) - T(measured_(k))) * T(inverse_sigma_);
    return true;
  }

  // The cost function with n + 1 parameter blocks of 7 and 3 residuals (defined in residuals.cc,
  // the one translation unit that instantiates the autodiff).
  static ceres::CostFunction* Create(std::shared_ptr<const RobotModel> model, const double* q,
                                     const Eigen::Vector3d& measured, double sigma);

 private:
  std::shared_ptr<const RobotModel> model_;
  JointMotions motions_;  // exp(s_i^ q_i) at this row's q, computed once
  Eigen::Vector3d measured_;
  double inverse_sigma_;
};

}  // namespace lpoe

#endif  // LPOE_POSITION_RESIDUAL_H_
