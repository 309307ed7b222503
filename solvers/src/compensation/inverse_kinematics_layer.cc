// The inverse kinematics of a model with a residual layer (lpoe/inverse_kinematics.h,
// docs/residual_layer.md): fixed-point iteration on the target around the parametric solve.
#include <algorithm>
#include <cmath>

#include "lpoe/inverse_kinematics.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/model/residual_layer.h"

namespace lpoe {

IkResult InverseKinematics::SolveThroughLayer(const IkTarget& target, const double* seed,
                                              double* q) const {
  const ResidualLayer& layer = *model_->residual_layer;
  const int n = model_->num_joints();
  constexpr int kMaxRounds = 20;
  double seed_copy[kMaxJoints], solved[kMaxJoints];
  std::copy(seed, seed + n, seed_copy);  // `q` may alias `seed`
  IkTarget moved = target;
  IkResult r = SolveParametric(target, seed_copy, solved);
  int iterations = r.iterations;
  Eigen::Vector3d correction = layer.Mean(solved, target.tool);
  for (int round = 0; round < kMaxRounds; ++round) {
    // A target the chain does not reach stays unreached a tenth of a millimetre away.
    if (r.status == IkStatus::kUnreachable) break;
    moved.position = target.position - correction;
    r = SolveParametric(moved, seed_copy, solved);
    iterations += r.iterations;
    const Eigen::Vector3d next = layer.Mean(solved, target.tool);
    const double change = (next - correction).norm();
    correction = next;
    if (change <= 0.1 * options_.position_tolerance) break;
  }
  r.iterations = iterations;
  // The error of the layered prediction (what the model predicts at the returned joints).
  r.position_error = (target.position - PredictToolPosition(*model_, solved, target.tool)).norm();
  if (r.status == IkStatus::kOk && r.position_error > 10 * options_.position_tolerance) {
    r.status = IkStatus::kUnreachable;
  }
  std::copy(solved, solved + n, q);
  return r;
}

}  // namespace lpoe
