#include "lpoe/model/prior.h"

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <glog/logging.h>

#include "lpoe/model/parameterization.h"

namespace lpoe {

Matrix6d DefaultFrameInformation(const RobotModel& model, int f, const PriorScales& scales,
                                 double scale) {
  const bool tool = f >= model.num_joints();
  const double rotation = 1e-3 * (tool ? scales.tool_rotation_mrad : scales.frame_rotation_mrad);
  const double translation = tool ? scales.tool_translation_mm : scales.frame_translation_mm;
  Vector6d d;
  d << Eigen::Vector3d::Constant(1.0 / (rotation * rotation * scale * scale)),
      Eigen::Vector3d::Constant(1.0 / (translation * translation * scale * scale));
  return d.asDiagonal();
}

Matrix6d FrameInformation(const ParameterPrior& prior, const RobotModel& model, int f) {
  if (f < static_cast<int>(prior.frame_information.size())) {
    return prior.frame_information[f] / (prior.scale * prior.scale);
  }
  return DefaultFrameInformation(model, f, prior.scales, prior.scale);
}

void FreeRegistrationDirections(const RobotModel& model, ParameterPrior* prior) {
  if (model.num_joints() < 1 || prior->frame_information.empty()) return;
  const double k2 = prior->scale * prior->scale;  // FrameInformation divides by it
  prior->frame_information[0] = DefaultFrameInformation(model, 0, prior->scales, 1.0) * k2;
  if (model.num_joints() < 2 || prior->frame_information.size() < 2) return;
  // Joint 1's centralizer (in the base frame's coordinates, after joint 1's motion) carried into
  // frame 2's coordinates: T_1 exp(S_1 q) exp(d) T_2 = T_1 exp(S_1 q) T_2 exp(Ad(T_2^-1) d).
  const Eigen::MatrixXd N = TwistCentralizer(model.joints[0].twist);
  if (N.cols() == 0) return;
  const Eigen::MatrixXd U = Adjoint(model.joints[1].origin.Inverse()) * N;
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(U);
  const Eigen::MatrixXd full = qr.householderQ() * Eigen::MatrixXd::Identity(6, 6);
  const Eigen::MatrixXd Q = full.leftCols(U.cols());
  const Eigen::MatrixXd B = full.rightCols(6 - U.cols());
  const Matrix6d& info = prior->frame_information[1];
  // The marginal information on B: (B^T C B)^-1 with C = info^-1 (info has full rank: a block's
  // directions without information get the tolerances, PriorFromCovariance).
  const Eigen::LDLT<Matrix6d> ldlt(info);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) return;
  const Eigen::MatrixXd C = ldlt.solve(Matrix6d::Identity());
  const Eigen::MatrixXd marginal = (B.transpose() * C * B).inverse();
  const Matrix6d fallback = DefaultFrameInformation(model, 1, prior->scales, 1.0) * k2;
  const Eigen::MatrixXd QQ = Q * Q.transpose();
  Matrix6d out = B * marginal * B.transpose() + QQ * fallback * QQ;
  prior->frame_information[1] = 0.5 * (out + out.transpose());
}

Vector6d FrameDeviation(const RobotModel& reference, const RobotModel& model, int f) {
  CHECK_EQ(reference.num_frames(), model.num_frames());
  const int n = model.num_joints();
  const SE3d& a = f < n ? reference.joints[f].origin : reference.tools[f - n].origin;
  const SE3d& b = f < n ? model.joints[f].origin : model.tools[f - n].origin;
  return LogSE3(a.Inverse() * b);
}

}  // namespace lpoe
