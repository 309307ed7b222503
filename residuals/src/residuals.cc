// The one translation unit that instantiates the autodiff residuals (they are slow to compile): one
// line per measurement kind at the end.
#include <glog/logging.h>

#include "lpoe/measurement_residual.h"

namespace lpoe {

template <typename Kind>
ceres::CostFunction* MeasurementResidual<Kind>::Create(
    std::shared_ptr<const RobotModel> model, const Kind& kind, const double* q,
    const typename Kind::Observation& observation, Eigen::MatrixXd joint_regressor,
    std::vector<int> block_sizes) {
  CHECK(model != nullptr);
  const int n = model->num_joints();
  int columns = 0;
  for (int k : block_sizes) {
    CHECK_GT(k, 0);
    columns += k;
  }
  CHECK(block_sizes.empty() || (joint_regressor.rows() == n && joint_regressor.cols() == columns))
      << "the joint regressor must be n x sum(block_sizes)";
  auto* cost = new CostFunction(new MeasurementResidual(
      std::move(model), kind, q, observation, std::move(joint_regressor), block_sizes));
  for (int i = 0; i <= n; ++i) cost->AddParameterBlock(kSe3AmbientSize);
  for (int k : block_sizes) cost->AddParameterBlock(k);
  cost->SetNumResiduals(Kind::kResiduals);
  return cost;
}

template class MeasurementResidual<PositionMeasurement>;
template class MeasurementResidual<PoseMeasurement>;

}  // namespace lpoe
