// The one translation unit that instantiates the autodiff residuals (they are slow to compile): one
// line per measurement kind at the end.
#include <memory>
#include <utility>
#include <vector>

#include <ceres/jet.h>
#include <glog/logging.h>

#include "lpoe/terms/joint_errors.h"
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
                 std::shared_ptr<const GravityTiltRow> tilt)
      : inner_(std::move(inner)),
        q_(q, q + n),
        regressor_t_(joint_regressor.transpose()),
        block_sizes_(block_sizes),
        tilt_(std::move(tilt)) {
    for (int i = 0; i <= n; ++i) mutable_parameter_block_sizes()->push_back(kSe3AmbientSize);
    for (int k : block_sizes_) mutable_parameter_block_sizes()->push_back(k);
    if (tilt_) mutable_parameter_block_sizes()->push_back(2);
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
    // The gravity tilt: the compliance offsets' change and its derivative in the tilt by Jets
    // through the templated prediction of joint_errors.h; the compliance columns at the tilt.
    const double* tilt = tilt_ ? parameters[n + 1 + blocks] : nullptr;
    std::vector<double> tilt_dq;      // n x 2, row-major: d(dq)/dt
    Eigen::MatrixXd compliance_dR;    // n x k_c: sum_a (g' - g)_a Z_a
    if (tilt_) {
      using Jet = ceres::Jet<double, 2>;
      const double* x = parameters[n + 1 + tilt_->block];
      const int k = block_sizes_[tilt_->block];
      const Jet t[2] = {Jet(tilt[0], 0), Jet(tilt[1], 1)};
      const Vector3<Jet> dg =
          TiltedGravity<Jet>(tilt_->gravity, tilt_->axes, t) - tilt_->gravity.cast<Jet>();
      const std::vector<Jet> x_jet(x, x + k);
      std::vector<Jet> ddq(n);
      ComplianceOffsets<Jet>(tilt_->Z, dg, x_jet.data(), ddq.data());
      tilt_dq.resize(static_cast<size_t>(2) * n);
      for (int j = 0; j < n; ++j) {
        q_eff[j] += ddq[j].a;
        tilt_dq[2 * j] = ddq[j].v(0);
        tilt_dq[2 * j + 1] = ddq[j].v(1);
      }
      compliance_dR = dg(0).a * tilt_->Z[0] + dg(1).a * tilt_->Z[1] + dg(2).a * tilt_->Z[2];
    }
    JointScratch<const double*, kStackJoints + 2> inner_parameters(n + 2);
    inner_parameters[0] = q_eff.data();
    for (int i = 0; i <= n; ++i) inner_parameters[i + 1] = parameters[i];
    bool need_q = false;
    for (int b = 0; jacobians != nullptr && b < blocks + (tilt_ ? 1 : 0); ++b) {
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
        const bool tilted = tilt_ && b == tilt_->block;
        JointScratch<double, 256> R(tilted ? k * n : 0);  // R_c + dR, row-major n x k
        if (tilted) {
          for (int j = 0; j < n; ++j) {
            for (int c = 0; c < k; ++c) {
              R[j * k + c] = regressor_t_(column + c, j) + compliance_dR(j, c);
            }
          }
        }
        for (int i = 0; i < m; ++i) {
          double* Ji = J + i * k;
          for (int c = 0; c < k; ++c) Ji[c] = 0;
          for (int j = 0; j < n; ++j) {
            const double a = J_q[i * n + j];
            const double* Rj = tilted ? &R[j * k] : &regressor_t_(column, j);
            for (int c = 0; c < k; ++c) Ji[c] += a * Rj[c];
          }
        }
      }
      column += k;
    }
    if (tilt_ && jacobians[n + 1 + blocks] != nullptr) {
      double* J = jacobians[n + 1 + blocks];  // row-major m x 2
      for (int i = 0; i < m; ++i) {
        for (int a = 0; a < 2; ++a) {
          double sum = 0;
          for (int j = 0; j < n; ++j) sum += J_q[i * n + j] * tilt_dq[2 * j + a];
          J[i * 2 + a] = sum;
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
  std::shared_ptr<const GravityTiltRow> tilt_;
};

}  // namespace

template <typename Kind>
ceres::CostFunction* MeasurementResidual<Kind>::Create(
    std::shared_ptr<const RobotModel> model, const Kind& kind, const double* q,
    const typename Kind::Observation& observation, Eigen::MatrixXd joint_regressor,
    std::vector<int> block_sizes, std::shared_ptr<const GravityTiltRow> tilt) {
  CHECK(model != nullptr);
  const int n = model->num_joints();
  int columns = 0;
  for (int k : block_sizes) {
    CHECK_GT(k, 0);
    columns += k;
  }
  CHECK(block_sizes.empty() || (joint_regressor.rows() == n && joint_regressor.cols() == columns))
      << "the joint regressor must be n x sum(block_sizes)";
  CHECK(tilt == nullptr ||
        (tilt->block >= 0 && tilt->block < static_cast<int>(block_sizes.size()) &&
         tilt->Z[0].rows() == n && tilt->Z[0].cols() == block_sizes[tilt->block]))
      << "the gravity tilt needs the compliance block's Z_a (n x k_c)";
  const bool joint_space = !block_sizes.empty();
  auto cost = std::make_unique<CostFunction>(
      new MeasurementResidual(std::move(model), kind, q, observation, joint_space));
  if (joint_space) cost->AddParameterBlock(n);  // q_eff, first (operator())
  for (int i = 0; i <= n; ++i) cost->AddParameterBlock(kSe3AmbientSize);
  cost->SetNumResiduals(Kind::kResiduals);
  if (!joint_space) return cost.release();
  return new JointSpaceCost(std::move(cost), q, n, joint_regressor, block_sizes,
                            std::move(tilt));
}

template class MeasurementResidual<PositionMeasurement>;
template class MeasurementResidual<PoseMeasurement>;

}  // namespace lpoe
