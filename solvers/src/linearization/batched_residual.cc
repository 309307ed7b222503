#include "linearization/batched_residual.h"

#include <utility>

#include <Eigen/Cholesky>
#include <Eigen/StdVector>
#include <glog/logging.h>

#include "lpoe/kinematics/kinematics.h"

namespace lpoe {
namespace internal {

BatchedPositionResidual::BatchedPositionResidual(std::shared_ptr<const RobotModel> model,
                                                 const Parameterization& p, std::vector<int> frames,
                                                 const MeasurementSet& data, int begin, int end,
                                                 double inverse_sigma)
    : model_(std::move(model)),
      p_(p),
      frames_(std::move(frames)),
      data_(data),
      begin_(begin),
      end_(end),
      inverse_sigma_(inverse_sigma) {
  CHECK(begin >= 0 && begin < end && end <= data.size());
  const int n = model_->num_joints();
  CHECK_GE(static_cast<int>(frames_.size()), n + 1);
  for (int i = 0; i < n; ++i) CHECK_EQ(frames_[i], i) << "the joint frames first, in order";
  for (int f : frames_) {
    manifolds_.emplace_back(p.basis[f]);
    mutable_parameter_block_sizes()->push_back(kSe3AmbientSize);
  }
  set_num_residuals(3 * (end - begin));
}

bool BatchedPositionResidual::Evaluate(double const* const* parameters, double* residuals,
                                       double** jacobians) const {
  const int n = model_->num_joints();
  const int blocks = static_cast<int>(frames_.size());
  RobotModel model = *model_;
  std::vector<int> block_of_tool(model.num_tools(), -1);
  for (int b = 0; b < blocks; ++b) {
    const int f = frames_[b];
    SE3d& T = f < n ? model.joints[f].origin : model.tools[f - n].origin;
    T = Se3FromArray(parameters[b]);
    if (f >= n) block_of_tool[f - n] = b;
  }
  const BasisJacobian bj(model, p_);
  const int P = bj.num_parameters();
  std::vector<FrameRt> scratch(n + 1);
  // M^+ of each block wanted, k x 7 padded with zero rows to 6 x 7 (fixed-size products per row).
  using Pinv = Eigen::Matrix<double, 6, kSe3AmbientSize>;
  std::vector<Pinv, Eigen::aligned_allocator<Pinv>> pinv(blocks, Pinv::Zero());
  const bool any_jacobian = jacobians != nullptr;
  if (any_jacobian) {
    for (int b = 0; b < blocks; ++b) {
      if (jacobians[b] == nullptr) continue;
      const int k = manifolds_[b].TangentSize();
      Eigen::Matrix<double, kSe3AmbientSize, Eigen::Dynamic, Eigen::RowMajor> M(kSe3AmbientSize,
                                                                                 k);
      manifolds_[b].PlusJacobian(parameters[b], M.data());
      const Eigen::MatrixXd MtM = M.transpose() * M;
      pinv[b].topRows(k) = MtM.llt().solve(M.transpose());
    }
  }
  Eigen::Matrix<double, 3, Eigen::Dynamic> J(3, P);
  for (int r = begin_; r < end_; ++r) {
    const int i = r - begin_;
    const int tool = data_.target(r);
    // The Jacobian is evaluated even for residuals only: the same residual bits either way.
    const Eigen::Vector3d predicted = bj.Position(data_.q(r), tool, J.data(), 3, scratch.data());
    const Eigen::Vector3d e = (predicted - data_.position(r)) * inverse_sigma_;
    residuals[3 * i] = e(0);
    residuals[3 * i + 1] = e(1);
    residuals[3 * i + 2] = e(2);
    if (!any_jacobian) continue;
    for (int b = 0; b < blocks; ++b) {
      if (jacobians[b] == nullptr) continue;
      Eigen::Map<Eigen::Matrix<double, 3, kSe3AmbientSize, Eigen::RowMajor>> Jb(
          jacobians[b] + static_cast<std::ptrdiff_t>(3 * kSe3AmbientSize) * i);
      const int f = frames_[b];
      if (f >= n && block_of_tool[tool] != b) {
        Jb.setZero();  // another tool than this row's
        continue;
      }
      Eigen::Matrix<double, 3, 6> Jf = Eigen::Matrix<double, 3, 6>::Zero();
      Jf.leftCols(manifolds_[b].TangentSize()) =
          inverse_sigma_ * J.middleCols(p_.offset[f], manifolds_[b].TangentSize());
      Jb.noalias() = Jf * pinv[b];
    }
  }
  return true;
}

}  // namespace internal
}  // namespace lpoe
