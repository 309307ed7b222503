// Measurement kind "pose": a tracker measures a tool frame's position and orientation (paper eqs.
// (17), (18)); see position_measurement.h for what a kind provides.
//
//   prediction   T_model = T_0,1(0) exp(s_1^ q_1) ... T_n-1,n(0) exp(s_n^ q_n) T_n,tool
//   error        y = log(T_measured T_model^-1)^vee = (omega, v)                 (eq. (17))
//   residual     r = diag(w, w, w, 1, 1, 1) y * inverse_sigma                     (6 rows)
//   linearized   W y = W A x,  A = [Ad_G_1 ... Ad_G_tool] B                      (eq. (18))
//
// w = orientation_weight (mm per rad) puts the rotation rows on the millimetre scale of the
// translation rows: 1 rad counts as w mm.
#ifndef LPOE_POSE_MEASUREMENT_H_
#define LPOE_POSE_MEASUREMENT_H_

#include <vector>

#include <Eigen/Core>

#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurement_kinds.h"
#include "lpoe/measurements/measurements.h"
#include "lpoe/model/parameterization.h"

namespace lpoe {

struct PoseMeasurement {
  static constexpr int kResiduals = 6;
  static constexpr int kFeatureSize = 0;  // no unknown feature: the tracker sees the base
  static constexpr MeasurementKindId kKind = MeasurementKindId::kPose;
  static constexpr const char* kLeftOutReason = nullptr;
  static constexpr DataKind kData = DataKind::kPose;
  using Observation = SE3d;
  // The CSV columns of a row's measured values: the position's, then the orientation's unit
  // quaternion (all four or none; a file with them is pose data).
  static constexpr const char* kColumns[] = {"x",      "y",      "z",     "quat_x",
                                             "quat_y", "quat_z", "quat_w"};

  double inverse_sigma = 1.0;
  double orientation_weight = 1000.0;

  // The kind with the solver's weights (see PositionMeasurement::Make).
  static PoseMeasurement Make(double inverse_sigma, double orientation_weight) {
    PoseMeasurement kind;
    kind.inverse_sigma = inverse_sigma;
    kind.orientation_weight = orientation_weight;
    return kind;
  }

  static Observation Observe(const MeasurementSet& data, int row) { return data.pose(row); }

  // The predicted tool frame from parameter blocks of 7 numbers (the n joint frames, then the tool).
  template <typename T, typename Motions>
  static SE3<T> Predict(int n, T const* const* blocks, const Motions& motions) {
    JointScratch<SE3<T>> frames(n);
    for (int i = 0; i < n; ++i) frames[i] = Se3FromArray(blocks[i]);
    SE3Accumulator<T> X;
    ForwardChain(n, [&frames](int i) -> const SE3<T>& { return frames[i]; }, motions, &X,
                 [](int, const SE3Accumulator<T>&) {});
    return X.X * Se3FromArray(blocks[n]);
  }

  template <typename T, typename Motions>
  void Residual(int n, T const* const* blocks, const Motions& motions, const Observation& measured,
                T* r) const {
    const SE3<T> model_pose = Predict<T>(n, blocks, motions);
    const Vector6<T> y = LogSE3(measured.cast<T>() * model_pose.Inverse());  // eq. (17)
    const T rotation_scale = T(orientation_weight * inverse_sigma);
    for (int k = 0; k < 3; ++k) r[k] = y(k) * rotation_scale;
    for (int k = 3; k < 6; ++k) r[k] = y(k) * T(inverse_sigma);
  }

  // Analytic path (see PositionMeasurement::Linearize): y = W log(T_measured T_model^-1) (6), the
  // frame columns of W A and, when J_q is not null, of W dT/dq (6 x n). Returns the position error
  // |t_measured - t_model| (mm). sin_q, cos_q as there.
  double Linearize(const BasisJacobian& bj, const double* q, int tool, const Observation& measured,
                   double* J, int ld, double* J_q, int ld_q, FrameRt* frames, double* y,
                   const double* sin_q = nullptr, const double* cos_q = nullptr) const {
    const SE3d T = bj.Pose(q, sin_q, cos_q, tool, J, ld, frames);
    if (J_q != nullptr) bj.PoseJointJacobian(frames, J_q, ld_q);
    Vector6d e = LogSE3(measured * T.Inverse());  // eq. (17)
    // Weight the rotation rows: 1 rad counts as orientation_weight mm.
    const double w = orientation_weight;
    e.head<3>() *= w;
    auto weigh = [&](double* M, int cols, int stride) {
      for (int c = 0; c < cols; ++c) {
        double* col = M + static_cast<std::ptrdiff_t>(c) * stride;
        col[0] *= w;
        col[1] *= w;
        col[2] *= w;
      }
    };
    weigh(J, bj.num_parameters(), ld);  // joint-block columns: overwritten by the caller
    if (J_q != nullptr) weigh(J_q, bj.num_joints(), ld_q);
    for (int i = 0; i < 6; ++i) y[i] = e(i);
    return (measured.t - T.t).norm();
  }

  // Simulation of a row (see PositionMeasurement::Simulate): noise_sigma mm per axis on the
  // position (three draws), then orientation_noise_sigma rad per axis on the orientation (three
  // draws, applied in the tool's frame: R exp(w^)).
  template <typename Gaussian>
  static void Simulate(const SE3d& actual, const double* q, int target, double noise_sigma,
                       double orientation_noise_sigma, Gaussian&& gaussian, MeasurementSet* data) {
    SE3d pose = actual;
    for (int k = 0; k < 3; ++k) pose.t(k) += noise_sigma * gaussian();
    Eigen::Vector3d w;
    for (int k = 0; k < 3; ++k) w(k) = orientation_noise_sigma * gaussian();
    pose.R = pose.R * ExpSO3(w);
    data->AddPose(q, pose, target);
  }

  // The row a perfect tracker gives at q on `model` (see PositionMeasurement::MeasureExactly).
  static void MeasureExactly(const RobotModel& model, const double* q, int target,
                             MeasurementSet* data) {
    data->AddPose(q, ToolPose(model, q, target), target);
  }
};

}  // namespace lpoe

#endif  // LPOE_POSE_MEASUREMENT_H_
