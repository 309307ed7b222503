// The one translation unit that instantiates the autodiff residuals (they are slow to compile): one
// line per measurement kind at the end.
#include <memory>
#include <utility>
#include <vector>

#include <ceres/jet.h>
#include <glog/logging.h>

#include "lpoe/joint_errors.h"
#include "lpoe/measurement_residual.h"

namespace lpoe {
namespace {

// The residual with joint-space blocks: q_eff = q + sum_b R_b x_b in double, the autodiff residual
// `inner` (blocks: the n + 1 frames, then q_eff) and the blocks' columns (dr/dq_eff) R_b.
class JointSpaceCost : public ceres::CostFunction {
 public:
  JointSpaceCost(std::unique_ptr<ceres::CostFunction> inner, const double* q, int n,
                 Eigen::MatrixXd joint_regressor, const std::vector<int>& block_sizes,
                 std::shared_ptr<const GravityTiltRow> tilt)
      : inner_(std::move(inner)),
        q_(q, q + n),
        regressor_(std::move(joint_regressor)),
        block_sizes_(block_sizes),
        tilt_(std::move(tilt)) {
    for (int i = 0; i <= n; ++i) mutable_parameter_block_sizes()->push_back(kSe3AmbientSize);
    for (int k : block_sizes_) mutable_parameter_block_sizes()->push_back(k);
    if (tilt_) mutable_parameter_block_sizes()->push_back(2);
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
    std::vector<const double*> inner_parameters(parameters, parameters + n + 1);
    inner_parameters.push_back(q_eff.data());
    bool need_q = false;
    for (int b = 0; jacobians != nullptr && b < blocks + (tilt_ ? 1 : 0); ++b) {
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
        const bool tilted = tilt_ && b == tilt_->block;
        for (int i = 0; i < m; ++i) {
          for (int c = 0; c < k; ++c) {
            double sum = 0;
            for (int j = 0; j < n; ++j) {
              sum += J_q[i * n + j] *
                     (regressor_(j, column + c) + (tilted ? compliance_dR(j, c) : 0.0));
            }
            J[i * k + c] = sum;
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
  Eigen::MatrixXd regressor_;  // n x sum(block_sizes)
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
  for (int i = 0; i <= n; ++i) cost->AddParameterBlock(kSe3AmbientSize);
  if (joint_space) cost->AddParameterBlock(n);  // q_eff
  cost->SetNumResiduals(Kind::kResiduals);
  if (!joint_space) return cost.release();
  return new JointSpaceCost(std::move(cost), q, n, std::move(joint_regressor), block_sizes,
                            std::move(tilt));
}

template class MeasurementResidual<PositionMeasurement>;
template class MeasurementResidual<PoseMeasurement>;

}  // namespace lpoe
