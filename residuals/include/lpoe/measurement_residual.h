// The Ceres residual of one measurement, for every measurement kind (position_measurement.h,
// pose_measurement.h): automatic differentiation through the kind's templated prediction.
//
// Parameter blocks, in order: the n joint frames and the measured tool's frame (7 numbers each,
// [qx qy qz qw tx ty tz], se3_manifold.h), then one block per joint-space term (k_b numbers x_b, the
// term's identifiable combinations). With joint-space blocks the chain is evaluated at
//
//   q_eff = q + sum_b R_b x_b,   R_b = Y_b(q) basis_b (n x k_b, fixed data of this row),
//
// the same cost as the linear solver's (whose columns for x_b are J_q(q_eff) R_b). The autodiff runs
// through the frames and q_eff only (q_eff is one more block of the functor: 7 (n + 1) + n
// directions, whatever the number of joint-space parameters), and the cost function Create returns
// adds the blocks' columns by the chain rule through the linear map: dr/dx_b = (dr/dq_eff) R_b.
// Without joint-space blocks the joint motions are computed once, at construction; with them once
// per q_eff, in double, for every autodiff pass that does not seed a q_eff direction (operator()).
//
// With a gravity tilt (GravityTiltRow, docs/joint_errors.md) one more block of 2 follows the
// joint-space blocks: the compliance block's offsets become bilinear,
//   q_eff += sum_a (g'(t) - g)_a Z_a x_c,
// its columns R_c + sum_a (g'(t) - g)_a Z_a, and the tilt's columns (dr/dq_eff) d(dq)/dt with
// d(dq)/dt by automatic differentiation (Jets) through the templated TiltedGravity and
// ComplianceOffsets of joint_errors.h.
#ifndef LPOE_MEASUREMENT_RESIDUAL_H_
#define LPOE_MEASUREMENT_RESIDUAL_H_

#include <memory>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <ceres/dynamic_autodiff_cost_function.h>

#include "lpoe/kinematics.h"
#include "lpoe/pose_measurement.h"
#include "lpoe/position_measurement.h"
#include "lpoe/robot_model.h"
#include "lpoe/se3_manifold.h"

namespace lpoe {

// One row's data for the gravity tilt: Z_a = Y_a(q) B_c (n x k_c, a = x, y, z of the base, B_c the
// compliance block's basis), the model's gravity and the tilt axes.
struct GravityTiltRow {
  int block = -1;  // the compliance block's index among the joint-space blocks
  Eigen::Vector3d gravity = Eigen::Vector3d::Zero();
  Eigen::Matrix<double, 3, 2> axes = Eigen::Matrix<double, 3, 2>::Zero();
  Eigen::MatrixXd Z[3];
};

template <typename Kind>
class MeasurementResidual {
 public:
  // Derivatives per autodiff pass. Each pass evaluates the whole chain on Jet<double, kStride>;
  // measured on the 6R chain (49 parameters, -O3, no -march): stride 1: 46 us per Jacobian,
  // 2: 19 us, 4: 51 us, 7: 90 us, 8: 90 us. Jet<double, 2> fills one SSE register and inlines.
  static constexpr int kStride = 2;
  using CostFunction = ceres::DynamicAutoDiffCostFunction<MeasurementResidual, kStride>;

  // `model` supplies the joints' twists (its frames are ignored: they are the parameters); `q`
  // holds model->num_joints() values. With `joint_values_block`, the functor's first block is the
  // n joint values the chain is evaluated at (q_eff), the frames follow, and `q` is the first
  // q_eff the motions are computed at.
  MeasurementResidual(std::shared_ptr<const RobotModel> model, const Kind& kind, const double* q,
                      const typename Kind::Observation& observation, bool joint_values_block)
      : model_(std::move(model)),
        kind_(kind),
        motions_(*model_, q),
        motions_q_(q, q + model_->num_joints()),
        observation_(observation),
        joint_values_block_(joint_values_block) {}

  // Blocks: without joint_values_block the n + 1 frames; with it q_eff, then the frames.
  //
  // With q_eff a block, the autodiff pass (DynamicAutoDiffCostFunction: kStride directions at a
  // time) seeds q_eff's directions in the first ceil(n / kStride) passes only (q_eff is the first
  // block); in the other passes q_eff's Jets have zero derivative parts, exp(s_i^ q_i) is a
  // constant of the pass and the chain is evaluated on the motions in double (MotionsAt),
  // computed once per q_eff: those passes cost what a geometric row's do, and give the same
  // derivatives as Jet motions (the motions' derivative parts are exactly zero; products with
  // them add exact zeros). A pass that seeds a q_eff direction computes the motions on Jets.
  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    const int n = model_->num_joints();
    if (!joint_values_block_) {
      kind_.Residual(n, parameters, motions_, observation_, residuals);
      return true;
    }
    const T* q = parameters[0];
    if (HasDerivatives(q, n)) {
      kind_.Residual(n, parameters + 1, JointMotions<T>(*model_, q), observation_, residuals);
    } else {
      kind_.Residual(n, parameters + 1, MotionsAt(q, n), observation_, residuals);
    }
    return true;
  }

  // The cost function: n + 1 blocks of 7  // The cost function: n + 1 blocks of 7, one block of block_sizes[b] per joint-space term, with
  // `tilt` one block of 2 (the gravity tilt) after them, and Kind::kResiduals residuals (defined in
  // residuals.cc, the one translation unit that instantiates the autodiff).
  static ceres::CostFunction* Create(std::shared_ptr<const RobotModel> model, const Kind& kind,
                                     const double* q,
                                     const typename Kind::Observation& observation,
                                     Eigen::MatrixXd joint_regressor = Eigen::MatrixXd(),
                                     std::vector<int> block_sizes = {},
                                     std::shared_ptr<const GravityTiltRow> tilt = nullptr);

 private:
  static bool HasDerivatives(const double*, int) { return false; }
  template <typename J>
  static bool HasDerivatives(const J* q, int n) {
    for (int i = 0; i < n; ++i) {
      if (!(q[i].v.array() == 0.0).all()) return true;
    }
    return false;
  }
  static double Value(double x) { return x; }
  template <typename J>
  static double Value(const J& x) {
    return x.a;
  }

  // The motions in double at the values of q (their scalar parts): computed again only when q
  // differs from the last values (an evaluation's passes, and the Jacobian that Ceres evaluates at
  // a point whose residuals it has evaluated, share them). The cache is this functor's own state:
  // every cost function Create returns belongs to one residual block, and Ceres evaluates a
  // residual block from one thread at a time (do not share one between residual blocks that may
  // be evaluated concurrently).
  template <typename T>
  const JointMotions<double>& MotionsAt(const T* q, int n) const {
    bool same = true;
    for (int i = 0; i < n && same; ++i) same = Value(q[i]) == motions_q_[i];
    if (!same) {
      for (int i = 0; i < n; ++i) motions_q_[i] = Value(q[i]);
      motions_ = JointMotions<double>(*model_, motions_q_.data());
    }
    return motions_;
  }

  std::shared_ptr<const RobotModel> model_;
  Kind kind_;
  // exp(s_i^ q_i): without a joint-values block at this row's q, computed once; with one at
  // motions_q_ (MotionsAt).
  mutable JointMotions<double> motions_;
  mutable std::vector<double> motions_q_;
  typename Kind::Observation observation_;
  bool joint_values_block_;
};

using PositionResidual = MeasurementResidual<PositionMeasurement>;
using PoseResidual = MeasurementResidual<PoseMeasurement>;

}  // namespace lpoe

#endif  // LPOE_MEASUREMENT_RESIDUAL_H_
