// Measurement kind "position": a tracker measures the origin of a tool (paper eqs. (26), (29), (30)).
//
//   prediction   P_model = T_0,1(0) exp(s_1^ q_1) ... T_n-1,n(0) exp(s_n^ q_n) p_tool
//   residual     r = (P_model - P_measured) * inverse_sigma                 (3 rows, autodiff path)
//   linearized   y = P_measured - P_model = J x,  J = [-P^ I3] [Ad_G_1 ... Ad_G_tool] B (eq. (29)-(30))
//
// A measurement kind (docs/architecture.md) is one header like this one: the observation it reads
// from a MeasurementSet, a templated prediction/residual on the parameter blocks (double or Jet frames,
// double or Jet joint values) for Ceres, and the analytic linearization for the linear solver. The
// tool's rotation does not enter (its block's manifold is restricted to translations).
#ifndef LPOE_POSITION_MEASUREMENT_H_
#define LPOE_POSITION_MEASUREMENT_H_

#include <Eigen/Core>

#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurement_kinds.h"
#include "lpoe/measurements/measurements.h"
#include "lpoe/model/parameterization.h"

namespace lpoe {

struct PositionMeasurement {
  static constexpr int kResiduals = 3;
  static constexpr int kFeatureSize = 0;  // no unknown feature: the tracker sees the base
  static constexpr MeasurementKindId kKind = MeasurementKindId::kPosition;
  static constexpr const char* kLeftOutReason = nullptr;
  static constexpr DataKind kData = DataKind::kPosition;
  using Observation = Eigen::Vector3d;
  // The CSV columns of a row's measured values (docs/file_formats.md; the table's line lists them
  // after the joint values): a tracker file with these and no quat_* column is position data.
  static constexpr const char* kColumns[] = {"x", "y", "z"};

  double inverse_sigma = 1.0;  // 1 / sigma (mm): whitening of the Ceres residuals

  // The kind with the solver's weights (the same signature for every tracker kind, so that the
  // solvers make whichever VisitTrackerKind gives them): position rows have no orientation weight.
  static PositionMeasurement Make(double inverse_sigma, double /*orientation_weight*/) {
    PositionMeasurement kind;
    kind.inverse_sigma = inverse_sigma;
    return kind;
  }

  static Observation Observe(const MeasurementSet& data, int row) { return data.position(row); }

  // The predicted tool position from parameter blocks of 7 numbers ([qx qy qz qw tx ty tz]: the n
  // joint frames, then the tool): the frames act on the point straight from their quaternions (no
  // rotation matrices; the manifold keeps each quaternion of unit norm).
  template <typename T, typename Motions>
  static Vector3<T> Predict(int n, T const* const* blocks, const Motions& motions) {
    JointScratch<QuaternionTransform<T>> frames(n);
    for (int i = 0; i < n; ++i) frames[i] = {blocks[i], blocks[i] + 4};
    const T* tool = blocks[n];
    return BackwardChain<T>(
        n, [&frames](int i) -> const QuaternionTransform<T>& { return frames[i]; }, motions,
        Vector3<T>(tool[4], tool[5], tool[6]));
  }

  template <typename T, typename Motions>
  void Residual(int n, T const* const* blocks, const Motions& motions, const Observation& measured,
                T* r) const {
    const Vector3<T> P = Predict<T>(n, blocks, motions);
    for (int k = 0; k < 3; ++k) r[k] = (P(k) - T(measured(k))) * T(inverse_sigma);
  }

  // Analytic path at the model of `bj` and joint values q: y = P_measured - P_model (3), the frame
  // columns of J (3 x bj.num_parameters(), leading dimension ld) and, when J_q is not null,
  // dP/dq (3 x n, leading dimension ld_q). Returns |y| (mm). sin_q, cos_q: sin and cos of q when
  // the caller has them (BasisJacobian::Position), else null.
  double Linearize(const BasisJacobian& bj, const double* q, int tool, const Observation& measured,
                   double* J, int ld, double* J_q, int ld_q, FrameRt* frames, double* y,
                   const double* sin_q = nullptr, const double* cos_q = nullptr) const {
    const Eigen::Vector3d P = bj.Position(q, sin_q, cos_q, tool, J, ld, frames);
    if (J_q != nullptr) bj.PositionJointJacobian(frames, J_q, ld_q);
    const Eigen::Vector3d e = measured - P;  // eq. (30)
    y[0] = e(0);
    y[1] = e(1);
    y[2] = e(2);
    return e.norm();
  }

  // Simulation of a row: the tracker reads the tool frame `actual` (the true pose at q, eq. (34))
  // with noise_sigma mm of noise per axis (three draws of gaussian(), N(0, 1), x then y then z),
  // appended to `data`. (orientation_noise_sigma: the pose kind's; not drawn here.)
  template <typename Gaussian>
  static void Simulate(const SE3d& actual, const double* q, int target, double noise_sigma,
                       double /*orientation_noise_sigma*/, Gaussian&& gaussian,
                       MeasurementSet* data) {
    Eigen::Vector3d P = actual.t;
    for (int k = 0; k < 3; ++k) P(k) += noise_sigma * gaussian();
    data->Add(q, P, target);
  }

  // The row a perfect tracker gives at q on `model` (the structural identifiability check's
  // generic data: only its Jacobian is used).
  static void MeasureExactly(const RobotModel& model, const double* q, int target,
                             MeasurementSet* data) {
    data->Add(q, ToolPosition(model, q, target), target);
  }
};

}  // namespace lpoe

#endif  // LPOE_POSITION_MEASUREMENT_H_
