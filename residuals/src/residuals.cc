// The one translation unit that instantiates the autodiff residuals (they are slow to compile): one
// line per measurement kind at the end.
#include <memory>
#include <utility>
#include <vector>

#include <ceres/jet.h>
#include <glog/logging.h>

#include "lpoe/measurement_residual.h"

namespace lpoe {
namespace {

// The residual with joint-space blocks: q_eff = q + sum_b R_b x_b in double, the autodiff residual
// `inner` (blocks: q_eff, then the n + 1 frames; MeasurementResidual::operator()) and the blocks'
// columns (dr/dq_eff) R_b. Scratch on the stack for up to kStackJoints joints.
class JointSpaceCost : public ceres::CostFunction {
 public:
  JointSpaceCost(std::unique_ptr<ceres::CostFunction> inner, const double* q, int n,
                 const Eigen::MatrixXd& joint_regressor, const std::vector<int>& block_sizes,
                 std::vector<std::shared_ptr<const BilinearRow>> bilinear)
      : inner_(std::move(inner)),
        q_(q, q + n),
        regressor_t_(joint_regressor.transpose()),
        block_sizes_(block_sizes),
        bilinear_(std::move(bilinear)) {
    for (int i = 0; i <= n; ++i) mutable_parameter_block_sizes()->push_back(kSe3AmbientSize);
    for (int k : block_sizes_) mutable_parameter_block_sizes()->push_back(k);
    for (const auto& e : bilinear_) {
      mutable_parameter_block_sizes()->push_back(e->effect->num_parameters());
    }
    set_num_residuals(inner_->num_residuals());
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    constexpr int kStackJoints = 16;
    const int n = static_cast<int>(q_.size());
    const int m = num_residuals();
    const int blocks = static_cast<int>(block_sizes_.size());
    // regressor_t_ is K x n column-major: joint j's row of R is contiguous (column j), so
    // q_eff_j = q_j + R(j, :) x reads it in order (one stream per joint: this row's R is not in
    // cache at the start of an evaluation, and strided reads of it stalled on every line).
    const int K = static_cast<int>(regressor_t_.rows());
    JointScratch<double, 256> x_all(K);
    {
      int column = 0;
      for (int b = 0; b < blocks; ++b) {
        const double* x = parameters[n + 1 + b];
        for (int c = 0; c < block_sizes_[b]; ++c) x_all[column++] = x[c];
      }
    }
    JointScratch<double, kStackJoints> q_eff(n);
    {
      const Eigen::Map<const Eigen::VectorXd> x(x_all.data(), K);
      for (int j = 0; j < n; ++j) q_eff[j] = q_[j] + regressor_t_.col(j).dot(x);
    }
    // The bilinear blocks: their change of the partners' offsets, the partners' columns at their
    // values and their own columns d(dq)/dt (BilinearJointColumns, as the linear solver).
    const int E = static_cast<int>(bilinear_.size());
    std::vector<Eigen::VectorXd> ddq(E);
    std::vector<Eigen::MatrixXd> partner_dR(E), D(E);
    for (int e = 0; e < E; ++e) {
      const BilinearRow& row = *bilinear_[e];
      BilinearJointColumns(*row.effect, parameters[n + 1 + blocks + e], row.Z,
                           parameters[n + 1 + row.block], &ddq[e], &partner_dR[e], &D[e]);
      for (int j = 0; j < n; ++j) q_eff[j] += ddq[e](j);
    }
    JointScratch<const double*, kStackJoints + 2> inner_parameters(n + 2);
    inner_parameters[0] = q_eff.data();
    for (int i = 0; i <= n; ++i) inner_parameters[i + 1] = parameters[i];
    bool need_q = false;
    for (int b = 0; jacobians != nullptr && b < blocks + E; ++b) {
      need_q = need_q || jacobians[n + 1 + b] != nullptr;
    }
    JointScratch<double, 6 * kStackJoints> J_q(need_q ? m * n : 0);  // row-major m x n
    JointScratch<double*, kStackJoints + 2> inner_jacobians(jacobians != nullptr ? n + 2 : 0);
    if (jacobians != nullptr) {
      inner_jacobians[0] = need_q ? J_q.data() : nullptr;
      for (int i = 0; i <= n; ++i) inner_jacobians[i + 1] = jacobians[i];
    }
    if (!inner_->Evaluate(inner_parameters.data(), residuals,
                          jacobians != nullptr ? inner_jacobians.data() : nullptr)) {
      return false;
    }
    if (!need_q) return true;
    // J_b = J_q R_b (row-major m x k_b): row i is sum_j J_q(i, j) R_b(j, :), the sum over j in
    // ascending order (vectorized over the block's columns).
    int column = 0;
    for (int b = 0; b < blocks; ++b) {
      const int k = block_sizes_[b];
      double* J = jacobians[n + 1 + b];
      if (J != nullptr) {
        bool bilinear_partner = false;
        for (int e = 0; e < E; ++e) bilinear_partner = bilinear_partner || bilinear_[e]->block == b;
        JointScratch<double, 256> R(bilinear_partner ? k * n : 0);  // R_p + dR, row-major n x k
        if (bilinear_partner) {
          for (int j = 0; j < n; ++j) {
            for (int c = 0; c < k; ++c) {
              double v = regressor_t_(column + c, j);
              for (int e = 0; e < E; ++e) {
                if (bilinear_[e]->block == b) v += partner_dR[e](j, c);
              }
              R[j * k + c] = v;
            }
          }
        }
        for (int i = 0; i < m; ++i) {
          double* Ji = J + i * k;
          for (int c = 0; c < k; ++c) Ji[c] = 0;
          for (int j = 0; j < n; ++j) {
            const double a = J_q[i * n + j];
            const double* Rj = bilinear_partner ? &R[j * k] : &regressor_t_(column, j);
            for (int c = 0; c < k; ++c) Ji[c] += a * Rj[c];
          }
        }
      }
      column += k;
    }
    for (int e = 0; e < E; ++e) {
      double* J = jacobians[n + 1 + blocks + e];  // row-major m x t
      if (J == nullptr) continue;
      const int t = static_cast<int>(D[e].cols());
      for (int i = 0; i < m; ++i) {
        for (int a = 0; a < t; ++a) {
          double sum = 0;
          for (int j = 0; j < n; ++j) sum += J_q[i * n + j] * D[e](j, a);
          J[i * t + a] = sum;
        }
      }
    }
    return true;
  }

 private:
  std::unique_ptr<ceres::CostFunction> inner_;
  std::vector<double> q_;
  Eigen::MatrixXd regressor_t_;  // sum(block_sizes) x n: R transposed
  std::vector<int> block_sizes_;
  std::vector<std::shared_ptr<const BilinearRow>> bilinear_;
};

}  // namespace

template <typename Kind>
ceres::CostFunction* MeasurementResidual<Kind>::Create(
    std::shared_ptr<const RobotModel> model, const Kind& kind, const double* q,
    const typename Kind::Observation& observation, Eigen::MatrixXd joint_regressor,
    std::vector<int> block_sizes, std::vector<std::shared_ptr<const BilinearRow>> bilinear) {
  CHECK(model != nullptr);
  const int n = model->num_joints();
  int columns = 0;
  for (int k : block_sizes) {
    CHECK_GT(k, 0);
    columns += k;
  }
  CHECK(block_sizes.empty() || (joint_regressor.rows() == n && joint_regressor.cols() == columns))
      << "the joint regressor must be n x sum(block_sizes)";
  for (const auto& e : bilinear) {
    CHECK(e != nullptr && e->effect != nullptr && e->block >= 0 &&
          e->block < static_cast<int>(block_sizes.size()) &&
          static_cast<int>(e->Z.size()) == e->effect->num_weights() && e->Z[0].rows() == n &&
          e->Z[0].cols() == block_sizes[e->block])
        << "a bilinear block needs its partner block's Z_a (n x k_p)";
  }
  const bool joint_space = !block_sizes.empty();
  auto cost = std::make_unique<CostFunction>(
      new MeasurementResidual(std::move(model), kind, q, observation, joint_space));
  if (joint_space) cost->AddParameterBlock(n);  // q_eff, first (operator())
  for (int i = 0; i <= n; ++i) cost->AddParameterBlock(kSe3AmbientSize);
  cost->SetNumResiduals(Kind::kResiduals);
  if (!joint_space) return cost.release();
  return new JointSpaceCost(std::move(cost), q, n, joint_regressor, block_sizes,
                            std::move(bilinear));
}

template class MeasurementResidual<PositionMeasurement>;
template class MeasurementResidual<PoseMeasurement>;

}  // namespace lpoe
