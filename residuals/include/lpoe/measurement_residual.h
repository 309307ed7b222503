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
// per q_eff, in double, for every autodiff pass (lifted to Jets in the passes that seed a q_eff
// direction: operator()).
//
// With bilinear blocks (BilinearRow, lpoe/terms/bilinear_term.h: the gravity tilt) one more block
// per effect follows the joint-space blocks: its partner block's offsets become bilinear,
//   q_eff += sum_a (w(t) - w(0))_a Z_a x_p,
// the partner's columns R_p + sum_a (w(t) - w(0))_a Z_a, and the effect's columns
// (dr/dq_eff) sum_a (dw/dt)_a Z_a x_p (BilinearJointColumns: the linear solver's arithmetic).
#ifndef LPOE_MEASUREMENT_RESIDUAL_H_
#define LPOE_MEASUREMENT_RESIDUAL_H_

#include <memory>
#include <type_traits>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <ceres/dynamic_autodiff_cost_function.h>

#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/pose_measurement.h"
#include "lpoe/measurements/position_measurement.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/se3_manifold.h"
#include "lpoe/terms/bilinear_term.h"

namespace lpoe {

// One row's data for a bilinear block: the effect, Z_a = Y_a(q) B_p (n x k_p, B_p the partner
// block's basis; BilinearJointEffect::RowRegressors).
struct BilinearRow {
  int block = -1;  // the partner block's index among the joint-space blocks
  std::shared_ptr<const BilinearJointEffect> effect;
  std::vector<Eigen::MatrixXd> Z;
};

// The joint motions exp(s_i^ q_i) at one q_eff in double, kept by the functor of a row with
// joint-space blocks (MeasurementResidual::MotionsAt): JointMotions<double> (revolute-z joints their
// (sin, cos), other joints their motion) that remembers its q. A Motions policy of kinematics.h for
// the passes that do not seed q_eff.
class JointValueMotions : public JointMotions<double> {
 public:
  void Set(const RobotModel& model, const double* q) {
    q_.assign(q, q + model.num_joints());
    JointMotions<double>::Set(model, q);
  }
  // Whether these are the motions at q (n values, compared exactly).
  bool At(const double* q, int n) const {
    if (static_cast<int>(q_.size()) != n) return false;
    for (int i = 0; i < n; ++i) {
      if (q[i] != q_[i]) return false;
    }
    return true;
  }

 private:
  std::vector<double> q_;
};

// The motions of a pass that seeds q_eff directions (Jets `q` with derivative parts): a revolute-z
// joint's sin and cos lifted from their values in double, (sin q, cos q dq) and (cos q, -sin q dq)
// -- the Jets Ceres's sin and cos return -- with no sin/cos call; other joints' motions computed on
// the Jets by their models as the chain reaches them.
template <typename J>
class LiftedMotions : public JointMotionsBase<LiftedMotions<J>> {
 public:
  LiftedMotions(const RobotModel& model, const JointValueMotions& values, const J* q)
      : model_(model), values_(values), q_(q), lifted_(model.num_joints()) {
    for (int i = 0; i < model.num_joints(); ++i) {
      if (!TakesSinCos(values.models(), i)) continue;
      const SinCosData<double>& d = values.DataOf(RevoluteZJoint(), i);
      lifted_[i].s.a = d.s;
      lifted_[i].s.v = d.c * q[i].v;
      lifted_[i].c.a = d.c;
      lifted_[i].c.v = -d.s * q[i].v;
    }
  }

  // The dispatcher and the data (JointMotionsBase).
  JointValueMotions::Models models() const { return values_.models(); }
  const SinCosData<J>& DataOf(RevoluteZJoint, int i) const { return lifted_[i]; }
  template <typename Model>
  SE3<J> DataOf(Model, int i) const {
    return Model::DataAt(model_.joints[i].twist, q_[i]);
  }

 private:
  const RobotModel& model_;
  const JointValueMotions& values_;
  const J* q_;
  // Set by the constructor, read only after (JointScratch has no const access).
  mutable JointScratch<SinCosData<J>> lifted_;
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
        observation_(observation),
        joint_values_block_(joint_values_block) {
    if (joint_values_block_) value_motions_.Set(*model_, q);
  }

  // Blocks: without joint_values_block the n + 1 frames; with it q_eff, then the frames.
  //
  // With q_eff a block, the autodiff pass (DynamicAutoDiffCostFunction: kStride directions at a
  // time) seeds q_eff's directions in the first ceil(n / kStride) passes only (q_eff is the first
  // block); in the other passes q_eff's Jets have zero derivative parts, exp(s_i^ q_i) is a
  // constant of the pass and the chain is evaluated on the motions in double (MotionsAt),
  // computed once per q_eff: those passes cost what a geometric row's do, and give the same
  // derivatives as Jet motions (the motions' derivative parts are exactly zero; products with
  // them add exact zeros). A pass that seeds a q_eff direction runs the chain on Jet motions,
  // lifted from the same values (LiftedMotions): the Jets sin and cos of q_eff would give.
  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    const int n = model_->num_joints();
    if (!joint_values_block_) {
      kind_.Residual(n, parameters, motions_, observation_, residuals);
      return true;
    }
    const T* q = parameters[0];
    const JointValueMotions& values = MotionsAt(q, n);
    if constexpr (std::is_same_v<T, double>) {
      kind_.Residual(n, parameters + 1, values, observation_, residuals);
    } else {
      if (HasDerivatives(q, n)) {
        kind_.Residual(n, parameters + 1, LiftedMotions<T>(*model_, values, q), observation_,
                       residuals);
      } else {
        kind_.Residual(n, parameters + 1, values, observation_, residuals);
      }
    }
    return true;
  }

  // The cost function: n + 1 blocks of 7, one block of block_sizes[b] per joint-space term, one
  // block per entry of `bilinear` after them (its effect's parameters), and Kind::kResiduals
  // residuals (defined in residuals.cc, the one translation unit that instantiates the autodiff).
  static ceres::CostFunction* Create(std::shared_ptr<const RobotModel> model, const Kind& kind,
                                     const double* q,
                                     const typename Kind::Observation& observation,
                                     Eigen::MatrixXd joint_regressor = Eigen::MatrixXd(),
                                     std::vector<int> block_sizes = {},
                                     std::vector<std::shared_ptr<const BilinearRow>> bilinear = {});

 private:
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
  const JointValueMotions& MotionsAt(const T* q, int n) const {
    JointScratch<double> values(n);
    for (int i = 0; i < n; ++i) values[i] = Value(q[i]);
    if (!value_motions_.At(values.data(), n)) value_motions_.Set(*model_, values.data());
    return value_motions_;
  }

  std::shared_ptr<const RobotModel> model_;
  Kind kind_;
  JointMotions<double> motions_;  // exp(s_i^ q_i) at this row's q (no joint-values block)
  mutable JointValueMotions value_motions_;  // at the last q_eff (MotionsAt)
  typename Kind::Observation observation_;
  bool joint_values_block_;
};

using PositionResidual = MeasurementResidual<PositionMeasurement>;
using PoseResidual = MeasurementResidual<PoseMeasurement>;

}  // namespace lpoe

#endif  // LPOE_MEASUREMENT_RESIDUAL_H_
