// The one translation unit that instantiates the autodiff residuals (they are slow to compile): one
// line per measurement kind at the end.
#include <memory>
#include <utility>
#include <vector>

#include <glog/logging.h>

#include "lpoe/measurement_residual.h"

namespace lpoe {
namespace {

// The residual with joint-space blocks: q_eff = q + sum_b R_b x_b in double, the autodiff residual
// `inner` (blocks: the n + 1 frames, then q_eff) and the blocks' columns (dr/dq_eff) R_b.
class JointSpaceCost : public ceres::CostFunction {
 public:
  JointSpaceCost(std::unique_ptr<ceres::CostFunction> inner, const double* q, int n,
                 Eigen::MatrixXd joint_regressor, const std::vector<int>& block_sizes)
      : inner_(std::move(inner)),
        q_(q, q + n),
        regressor_(std::move(joint_regressor)),
        block_sizes_(block_sizes) {
    for (int i = 0; i <= n; ++i) mutable_parameter_block_sizes()->push_back(kSe3AmbientSize);
    for (int k : block_sizes_) mutable_parameter_block_sizes()->push_back(k);
    set_num_residuals(inner_->num_residuals());
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const int n = static_cast<int>(q_.size());
    const int m = num_residuals();
    const int blocks = static_cast<int>(block_sizes_.size());
    std::vector<double> q_eff(q_);
    int column = 0;
    for (int b = 0; b < blocks; ++b) {
      const double* x = parameters[n + 1 + b];
      for (int c = 0; c < block_sizes_[b]; ++c, ++column) {
        for (int j = 0; j < n; ++j) q_eff[j] += regressor_(j, column) * x[c];
      }
    }
    std::vector<const double*> inner_parameters(parameters, parameters + n + 1);
    inner_parameters.push_back(q_eff.data());
    bool need_q = false;
    for (int b = 0; jacobians != nullptr && b < blocks; ++b) {
      need_q = need_q || jacobians[n + 1 + b] != nullptr;
    }
    std::vector<double> J_q(need_q ? static_cast<size_t>(m) * n : 0);  // row-major m x n
    std::vector<double*> inner_jacobians;
    if (jacobians != nullptr) {
      inner_jacobians.assign(jacobians, jacobians + n + 1);
      inner_jacobians.push_back(need_q ? J_q.data() : nullptr);
    }
    if (!inner_->Evaluate(inner_parameters.data(), residuals,
                          jacobians != nullptr ? inner_jacobians.data() : nullptr)) {
      return false;
    }
    if (!need_q) return true;
    column = 0;
    for (int b = 0; b < blocks; ++b) {
      const int k = block_sizes_[b];
      double* J = jacobians[n + 1 + b];  // row-major m x k
      if (J != nullptr) {
        for (int i = 0; i < m; ++i) {
          for (int c = 0; c < k; ++c) {
            double sum = 0;
            for (int j = 0; j < n; ++j) sum += J_q[i * n + j] * regressor_(j, column + c);
            J[i * k + c] = sum;
          }
        }
      }
      column += k;
    }
    return true;
  }

 private:
  std::unique_ptr<ceres::CostFunction> inner_;
  std::vector<double> q_;
  Eigen::MatrixXd regressor_;  // n x sum(block_sizes)
  std::vector<int> block_sizes_;
};

}  // namespace

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
  const bool joint_space = !block_sizes.empty();
  auto cost = std::make_unique<CostFunction>(
      new MeasurementResidual(std::move(model), kind, q, observation, joint_space));
  for (int i = 0; i <= n; ++i) cost->AddParameterBlock(kSe3AmbientSize);
  if (joint_space) cost->AddParameterBlock(n);  // q_eff
  cost->SetNumResiduals(Kind::kResiduals);
  if (!joint_space) return cost.release();
  return new JointSpaceCost(std::move(cost), q, n, std::move(joint_regressor), block_sizes);
}

template class MeasurementResidual<PositionMeasurement>;
template class MeasurementResidual<PoseMeasurement>;

}  // namespace lpoe
