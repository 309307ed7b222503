// Internal to lpoe_solvers: many position measurements in one Ceres residual block, with the
// analytic Jacobian of the shared measurement model (BasisJacobian, the linear solver's) instead of
// one autodiff block per row. For large data sets (docs/performance.md): Ceres's per-block overhead
// (bookkeeping, scratch, dispatch) is paid once per batch, and a batch is one task of Ceres's
// threads.
#ifndef LPOE_SOLVERS_SRC_BATCHED_RESIDUAL_H_
#define LPOE_SOLVERS_SRC_BATCHED_RESIDUAL_H_

#include <memory>
#include <vector>

#include <Eigen/Core>
#include <ceres/cost_function.h>

#include "lpoe/measurements/measurements.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/se3_manifold.h"

namespace lpoe {
namespace internal {

// Residuals r_i = (P_model(q_i) - P_i) / sigma of rows [begin, end) of `data` (3 per row, in row
// order): the same residuals as PositionResidual's, one block for all of them. The parameter blocks
// are the frames listed in `frames` (frame indices of `model`: joints 0..n-1, then tools), each
// [qx qy qz qw tx ty tz] with Se3Manifold(p.basis[f]); they must include every joint and the tool
// of every row in the range (a tool no row of the batch measures gets zero Jacobian rows).
//
// Jacobians: BasisJacobian gives dP/dx_f in each frame's tangent basis, J_f (3 x k). Ceres wants
// the derivative in the 7 ambient numbers and multiplies it by the manifold's PlusJacobian M
// (7 x k); the block returns J_f M^+ (M^+ = (M^T M)^-1 M^T), whose product with M is J_f exactly
// (M has full column rank). The component along directions the manifold cannot move (quaternion
// scale, rotations left out of the basis) is left out; Ceres never uses it.
//
// No robust loss: Ceres applies a LossFunction to a block's whole squared norm, so a loss on a
// batch would weigh its rows together. The builder keeps one block per row when a loss is set.
class BatchedPositionResidual : public ceres::CostFunction {
 public:
  BatchedPositionResidual(std::shared_ptr<const RobotModel> model, const Parameterization& p,
                          std::vector<int> frames, const MeasurementSet& data, int begin, int end,
                          double inverse_sigma);

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  std::shared_ptr<const RobotModel> model_;
  const Parameterization& p_;
  std::vector<int> frames_;
  std::vector<Se3Manifold> manifolds_;  // one per parameter block
  const MeasurementSet& data_;
  int begin_ = 0;
  int end_ = 0;
  double inverse_sigma_ = 1.0;
};

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_SOLVERS_SRC_BATCHED_RESIDUAL_H_
