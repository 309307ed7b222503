// The one translation unit that instantiates the autodiff residuals (they are slow to compile).
#include <glog/logging.h>

#include "lpoe/pose_residual.h"
#include "lpoe/position_residual.h"

namespace lpoe {

ceres::CostFunction* PositionResidual::Create(std::shared_ptr<const RobotModel> model,
                                              const double* q, const Eigen::Vector3d& measured,
                                              double sigma) {
  CHECK(model != nullptr);
  CHECK_GT(sigma, 0.0);
  const int n = model->num_joints();
  auto* cost = new CostFunction(new PositionResidual(std::move(model), q, measured, sigma));
  for (int i = 0; i <= n; ++i) cost->AddParameterBlock(kSe3AmbientSize);
  cost->SetNumResiduals(kNumResiduals);
  return cost;
}

ceres::CostFunction* PoseResidual::Create(std::shared_ptr<const RobotModel> model, const double* q,
                                          const SE3d& measured, double sigma,
                                          double orientation_weight) {
  CHECK(model != nullptr);
  CHECK_GT(sigma, 0.0);
  CHECK_GT(orientation_weight, 0.0);
  const int n = model->num_joints();
  auto* cost = new CostFunction(
      new PoseResidual(std::move(model), q, measured, sigma, orientation_weight));
  for (int i = 0; i <= n; ++i) cost->AddParameterBlock(kSe3AmbientSize);
  cost->SetNumResiduals(kNumResiduals);
  return cost;
}

}  // namespace lpoe
